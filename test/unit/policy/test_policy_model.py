"""The shipped policy model and what the runtime accepts: exported == trained, metadata
complete, models that do not fit refused with one line."""
from pathlib import Path

import numpy as np
import pytest

from ball_balance.control.references import RefSample
from ball_balance.policy.observation import (
    HISTORY,
    ObservationBuilder,
    axis_size,
    correction_weight,
    flat_names,
    low_gain_share,
)
from ball_balance.policy.params import DEFAULT_MODEL_RATE_HZ, POLICY_SCHEMA
from ball_balance.policy.tilt_law import ACTION_KIND, base_pid_mismatch, delay_share, load_tilt_law
from controller_manager_py.controllers.policy_model import PolicyModelError, PolicyRunner, read_model
from controller_manager_py.parameters import validate

ROOT = Path(__file__).resolve().parents[3]
DATA = Path(__file__).resolve().parent / "data"
SHIPPED = ROOT / "config" / "policies" / "residual_tilt.onnx"   # the file in the repository


def policy_values(**overrides):
    import yaml

    values = yaml.safe_load((ROOT / "config" / "policy.yaml").read_text())["ball_balance_policy"]["ros__parameters"]
    values.update(overrides)
    return dict(validate(POLICY_SCHEMA, values))


def configured_rate_hz() -> float:
    return float(policy_values()["control_rate_hz"])


def load_ball_runner(path):
    return PolicyRunner.load(path, observation_names=flat_names(), action_kind=ACTION_KIND, action_count=2,
                             rate_hz=configured_rate_hz())


def test_exported_model_gives_the_training_time_actions_on_recorded_observations():
    recorded = np.load(SHIPPED.with_suffix(".check.npz"))
    runner = load_ball_runner(SHIPPED)
    got = np.array([runner.infer(obs) for obs in recorded["observations"]])
    assert got.shape == recorded["actions"].shape
    np.testing.assert_allclose(got, recorded["actions"], atol=1e-5, rtol=0)


def test_shipped_model_metadata_says_how_it_was_made_and_how_to_run_it():
    _, md = read_model(SHIPPED)
    assert md.observation.names == flat_names() and md.observation.history == HISTORY
    assert len(md.observation.mean) == len(md.observation.std) == 2 * axis_size()
    assert md.action.kind == ACTION_KIND and md.action.size == 2
    assert all(s > 0 for s in md.action.scale) and md.action.low == [-0.15, -0.15]
    assert md.rate_hz == configured_rate_hz() == DEFAULT_MODEL_RATE_HZ   # the node's default runs it
    training = md.training
    for key in ("seed", "commit", "domains", "method", "wall_time_s", "base_pid"):
        assert key in training, key
    assert training["domains"]["latency_s"][1] >= 0.2 and training["domains"]["gravity_scale"][0] <= 0.5
    assert SHIPPED.stat().st_size < 150_000   # small: two 128-wide layers (85 kB) and the training record


def test_configured_pid_matches_the_one_the_model_was_trained_on():
    _, md = read_model(SHIPPED)
    assert base_pid_mismatch(md.training, policy_values()) is None
    law = load_tilt_law(policy_values())
    assert law.runner.where.endswith("residual_tilt.onnx")
    # the PID under the residual is the one it was trained on
    assert law.pid.gains.ki == md.training["base_pid"]["ki"]


def test_model_trained_on_another_pid_is_refused():
    with pytest.raises(PolicyModelError, match="trained on a different PID .*kp"):
        load_tilt_law(policy_values(kp=3.0))


def test_model_at_another_rate_is_refused():
    with pytest.raises(PolicyModelError, match=f"trained at {configured_rate_hz():g} Hz, configured at 100 Hz"):
        load_tilt_law(policy_values(control_rate_hz=100.0))


def test_model_whose_graph_width_differs_from_its_metadata_is_refused():
    width = len(flat_names())
    with pytest.raises(PolicyModelError, match=f"input width {width - 2} but the metadata names {width}"):
        read_model(DATA / "wrong_width.onnx")


def test_model_with_another_observation_layout_is_refused():
    shorter, width = len(flat_names(HISTORY - 1)), len(flat_names())
    with pytest.raises(PolicyModelError, match=f"takes {shorter} observations, this controller gives {width}"):
        load_ball_runner(DATA / "other_layout.onnx")


def test_model_without_metadata_is_refused():
    with pytest.raises(PolicyModelError, match="metadata lacks"):
        load_ball_runner(DATA / "no_metadata.onnx")


def test_missing_model_file_is_refused_with_its_path(tmp_path):
    with pytest.raises(PolicyModelError, match="no such file"):
        load_ball_runner(tmp_path / "absent.onnx")


def test_model_with_another_action_kind_is_refused():
    with pytest.raises(PolicyModelError, match="action kind 'absolute'"):
        PolicyRunner.load(DATA / "absolute_joint.onnx", action_kind=ACTION_KIND)


def _ref():
    return RefSample(np.zeros(2), np.zeros(2), np.zeros(2))


def test_non_finite_observation_holds_the_last_tilt_and_is_counted():
    law = load_tilt_law(policy_values())
    for _ in range(60):
        u = law.step((0.03, -0.02), (0.0, 0.0), _ref(), 0.02, 0.03)
    held = law.held_count
    for bad in (np.nan, np.inf):
        assert law.step((bad, 0.0), (0.0, 0.0), _ref(), 0.02, 0.03) == u
    assert law.step((0.0, 0.0), (0.0, 0.0), _ref(), 0.02, np.nan) == u
    assert law.held_count == held + 3


def test_correction_blends_in_after_engagement():
    law = load_tilt_law(policy_values(policy_blend_s=1.0))
    law.step((0.05, 0.05), (0.0, 0.0), _ref(), 0.02, 0.03)
    assert law.blend == pytest.approx(0.02)
    first = np.abs(law.last_correction).max()
    assert first <= 0.02 * 0.1 + 1e-12
    law.reset()
    assert law.blend == 0.0


def test_correction_weight_is_whole_near_the_reference_and_none_beyond_twice_the_fade_distance():
    errors = np.array([[0.003, 0.004], [0.0, 0.0075], [-0.006, 0.008], [0.05, 0.0]])   # 5, 7.5, 10, 50 mm
    np.testing.assert_allclose(correction_weight(errors, 0.005), [1.0, 0.5, 0.0, 0.0])
    np.testing.assert_allclose(correction_weight(errors, 0.0), [1.0] * 4)


def test_correction_weight_with_an_onset_is_none_near_the_reference_and_whole_beyond_twice_it():
    errors = np.array([[0.003, 0.004], [0.0, 0.0075], [-0.006, 0.008], [0.05, 0.0]])   # 5, 7.5, 10, 50 mm
    np.testing.assert_allclose(correction_weight(errors, 0.0, 0.005), [0.0, 0.5, 1.0, 1.0])
    np.testing.assert_allclose(correction_weight(errors, 0.03, 0.005), [0.0, 0.5, 1.0, 2.0 - 50.0 / 30.0])


def test_correction_weight_on_a_weak_plant_applies_near_the_reference_too():
    near = np.zeros((4, 2))   # on the reference: no correction from the distance
    ratios = np.array([1.2, 0.8, np.sqrt(0.8 * 0.64), 0.5])   # above, at the onset, halfway in log, below its square
    np.testing.assert_allclose(correction_weight(near, 0.0, 0.005, ratios, 0.8), [0.0, 0.0, 0.5, 1.0], atol=1e-12)
    np.testing.assert_allclose(low_gain_share(ratios, 0.8), [0.0, 0.0, 0.5, 1.0], atol=1e-12)
    np.testing.assert_allclose(correction_weight(near, 0.0, 0.005, ratios, 0.0), [0.0] * 4)   # not asked for
    far = np.array([[0.05, 0.0]] * 4)   # the distance's share is already whole
    np.testing.assert_allclose(correction_weight(far, 0.0, 0.005, ratios, 0.8), [1.0] * 4)


def test_the_law_applies_the_models_correction_fade():
    _, md = read_model(SHIPPED)
    law = load_tilt_law(policy_values(policy_blend_s=0.0))
    assert law.correction_fade_m == md.training.get("correction_fade_error_m", 0.0)
    corrections = {}
    for fade_m in (0.0, 0.005):
        law.reset()
        law.correction_fade_m = fade_m
        for _ in range(30):   # 30 mm off, as after a push
            law.step((0.03, -0.01), (0.2, 0.0), _ref(), 1.0 / 60.0, 0.03)
        corrections[fade_m] = law.last_correction.copy()
    assert np.abs(corrections[0.0]).max() > 0.0
    np.testing.assert_array_equal(corrections[0.005], [0.0, 0.0])


def test_the_law_applies_the_models_correction_onset():
    _, md = read_model(SHIPPED)
    law = load_tilt_law(policy_values(policy_blend_s=0.0))
    assert law.correction_onset_m == md.training.get("correction_onset_error_m", 0.0)
    law.correction_fade_m = 0.0
    corrections = {}
    for onset_m in (0.0, 0.005):
        law.reset()
        law.correction_onset_m = onset_m
        for _ in range(30):   # 3 mm off: within the onset
            law.step((0.003, -0.001), (0.02, 0.0), _ref(), 1.0 / 60.0, 0.03)
        corrections[onset_m] = law.last_correction.copy()
    assert np.abs(corrections[0.0]).max() > 0.0
    np.testing.assert_array_equal(corrections[0.005], [0.0, 0.0])


def test_the_law_corrects_near_the_reference_on_a_weak_plant():
    _, md = read_model(SHIPPED)
    law = load_tilt_law(policy_values(policy_blend_s=0.0))
    assert law.low_gain_onset == md.training.get("correction_low_gain_onset", 0.0)
    law.correction_fade_m, law.correction_onset_m, law.low_gain_onset = 0.0, 0.005, 0.8
    corrections = {}
    for k_g in (law.k_g, 0.5 * law.k_g):   # 3 mm off (within the onset) on the tuned plant and at half gain
        law.reset()
        for _ in range(30):
            law.step((0.003, -0.001), (0.02, 0.0), _ref(), 1.0 / 60.0, 0.03, k_g)
        corrections[k_g] = law.last_correction.copy()
    np.testing.assert_array_equal(corrections[law.k_g], [0.0, 0.0])
    assert np.abs(corrections[0.5 * law.k_g]).max() > 0.0


def test_delay_share_is_whole_up_to_the_limit_and_none_beyond_the_fade():
    assert [delay_share(d, 0.17) for d in (0.0, 0.17, 0.18, 0.19, 0.25)] == pytest.approx([1.0, 1.0, 0.5, 0.0, 0.0])
    assert delay_share(5.0, 0.0) == 1.0   # no limit


def test_the_law_leaves_a_long_delay_to_the_pid():
    law = load_tilt_law(policy_values(policy_blend_s=0.0))
    assert law.max_delay_s == policy_values()["policy_max_delay_s"] > 0.0
    law.correction_fade_m = 0.0
    corrections = {}
    for delay_s in (0.05, 0.25):
        law.reset()
        for _ in range(30):   # 30 mm off, where the correction applies
            law.step((0.03, -0.01), (0.2, 0.0), _ref(), 1.0 / 60.0, 0.03, delay_s=delay_s)
        corrections[delay_s] = law.last_correction.copy()
    assert np.abs(corrections[0.05]).max() > 0.0
    np.testing.assert_array_equal(corrections[0.25], [0.0, 0.0])


def test_observation_layout_puts_the_newest_sample_first():
    b = ObservationBuilder(1)
    b.record_tilt(np.array([[0.01, 0.02]]))
    b.build(np.array([[0.1, 0.2]]), np.zeros((1, 2)), np.zeros((1, 2)), np.zeros((1, 2)), 0.0)
    obs = b.build(np.array([[0.3, 0.4]]), np.array([[5.0, 6.0]]), np.zeros((1, 2)), np.zeros((1, 2)), 0.04)[0]
    named = dict(zip(flat_names(), obs))
    assert len(obs) == len(flat_names())
    assert named["x.error_m[0]"] == 0.3 and named["x.error_m[1]"] == 0.1 and named["y.error_m[0]"] == 0.4
    assert named["x.tilt_rad[0]"] == 0.01 and named["y.tilt_rad[0]"] == 0.02
    assert named["y.vel_error_m_s"] == 6.0 and named["x.age_s"] == 0.04
    assert named["x.gain_ratio"] == named["y.gain_ratio"] == 1.0   # no plant estimate: the tuned gain
    obs = b.build(np.zeros((1, 2)), np.zeros((1, 2)), np.zeros((1, 2)), np.zeros((1, 2)), 0.0, 0.5)[0]
    assert dict(zip(flat_names(), obs))["y.gain_ratio"] == 0.5
