"""The parameters the project's nodes run with, from its config/ folder: a controller's
(schema defaults + config/<controller>.yaml + a reference + overrides) and the tracker's
(config/ball_tracker.yaml). The benchmark's episodes and the policy's training plant both
build their controllers and filters from them."""
from __future__ import annotations

from pathlib import Path

from ball_balance.control import config as control_config
from ball_balance.policy.params import POLICY_SCHEMA
from controller_manager_py.parameters import validate

CONFIG_DIR = Path(__file__).resolve().parents[1] / "config"
PATHS_DIR = CONFIG_DIR / "paths"   # CSV paths of REFERENCES
REFERENCES = {
    "stationary": dict(reference_kind="stationary"),
    "circle": dict(reference_kind="circle", reference_radius_m=0.10, reference_period_s=10.0),
    "figure_eight": dict(reference_kind="figure_eight", reference_radius_m=0.10, reference_period_s=12.0),
    # a 0.15 m square (the radius is its half side), one lap in 8 s
    "square": dict(reference_kind="square", reference_radius_m=0.075, reference_period_s=8.0),
    # a CSV path: a spiral in and out, r = 0.10 -> 0.03 -> 0.10 m, 2 turns in 16 s, a row every
    # 0.2 s (config/paths/make_spiral.py writes it); the file from the repository, whatever the cwd
    "spiral": dict(reference_kind="csv", reference_csv_path=str(PATHS_DIR / "spiral.csv")),
}


def controller_schema(controller: str):
    """The parameter schema of a controller's node: the PID's, the MPC's or the policy's; a
    controller without one of its own gets the PID's."""
    return {"mpc": control_config.MPC_NODE_SCHEMA, "policy": POLICY_SCHEMA}.get(controller, control_config.PID_SCHEMA)


def controller_values(controller: str, reference: str, overrides=()) -> dict:
    """Validated controller parameters: schema defaults + config/<controller>.yaml (its node's
    ros__parameters) + the reference + overrides."""
    import yaml

    path = CONFIG_DIR / f"{controller}.yaml"
    values = {}
    if path.exists():
        loaded = yaml.safe_load(path.read_text()) or {}
        nodes = [v["ros__parameters"] for v in loaded.values() if isinstance(v, dict) and "ros__parameters" in v]
        values = dict(nodes[0]) if nodes else {}
    values.update(REFERENCES[reference])
    values.update(dict(overrides))
    return dict(validate(controller_schema(controller), values, allow_unknown=True))


def tracker_values() -> dict:
    """The tracker parameters the graph runs with (config/ball_tracker.yaml), for both modes."""
    import yaml

    path = CONFIG_DIR / "ball_tracker.yaml"
    if not path.exists():
        return {}
    return dict(yaml.safe_load(path.read_text())["ball_tracker"]["ros__parameters"])
