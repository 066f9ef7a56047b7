"""Writes the small ONNX models the policy tests load (needs the `onnx` package of
requirements/train.txt; the files are committed, so the tests themselves do not):

    python test/unit/policy/data/make_models.py
"""
from pathlib import Path

import numpy as np

from ball_balance.policy.export import write_mlp_onnx
from ball_balance.policy.observation import flat_names
from controller_manager_py.controllers import policy_model as meta

HERE = Path(__file__).resolve().parent
TRAINING = {"method": "test fixture", "seed": 0, "commit": "none"}


def mlp(rng, n_in, hidden, n_out=1):
    return [(rng.normal(0, 0.3, (hidden, n_in)), rng.normal(0, 0.1, hidden)),
            (rng.normal(0, 0.3, (n_out, hidden)), rng.normal(0, 0.1, n_out))]


def metadata(names, actions, kind="residual_tilt", rate_hz=50.0, scale=0.1, low=-0.15, high=0.15, training=TRAINING):
    return meta.make_metadata(meta.ObservationSpec(names=names, mean=[0.0] * len(names), std=[1.0] * len(names)),
                              meta.ActionSpec(names=actions, kind=kind, unit="rad", scale=[scale] * len(actions),
                                              low=[low] * len(actions), high=[high] * len(actions)),
                              rate_hz, training)


def main():
    import onnx

    rng = np.random.default_rng(0)
    names = flat_names()
    half = len(names) // 2
    tilt = ["x.tilt_correction", "y.tilt_correction"]
    # graph narrower than its metadata says
    write_mlp_onnx(HERE / "wrong_width.onnx", mlp(rng, half - 1, 4), half - 1, 2, metadata(names, tilt))
    # consistent, but another layout than the ball controller's (one history step less)
    other = [n for n in names if not n.endswith("[15]")]
    write_mlp_onnx(HERE / "other_layout.onnx", mlp(rng, len(other) // 2, 4), len(other) // 2, 2,
                        metadata(other, tilt))
    # no metadata at all
    path = HERE / "no_metadata.onnx"
    write_mlp_onnx(path, mlp(rng, half, 4), half, 2, metadata(names, tilt))
    model = onnx.load(str(path))
    del model.metadata_props[:]
    onnx.save(model, str(path))
    # a generic absolute policy: the first joint's position from its own position and two inputs
    joint = "shoulder_pan_joint/position"
    write_mlp_onnx(HERE / "absolute_joint.onnx", mlp(rng, 3, 4), 3, 1,
                   metadata([joint, "target", "target[1]"], [joint], kind="absolute", rate_hz=100.0, scale=1.0,
                            low=-1.0, high=1.0))


if __name__ == "__main__":
    main()
