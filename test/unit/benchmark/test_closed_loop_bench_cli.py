"""closed_loop_bench's lists: comma-separated names, groups expanded, unknown names refused
with one line; the controller list is whatever the control pipeline declares."""
import importlib.util
from pathlib import Path

import pytest

PATH = Path(__file__).resolve().parents[3] / "benchmarks" / "closed_loop_bench.py"
spec = importlib.util.spec_from_file_location("closed_loop_bench", PATH)
bench = importlib.util.module_from_spec(spec)
spec.loader.exec_module(bench)


def test_names_are_comma_separated_and_groups_expand():
    assert bench.names("pid,mpc policy", None, "controller") == ["pid", "mpc", "policy"]
    domains = bench.names("standard,harsh", set(bench.DOMAINS), "domain", bench.DOMAIN_GROUPS)
    assert domains[0] == "standard" and "extreme_dr" in domains and len(domains) == len(set(domains))


def test_unknown_names_are_refused_naming_them():
    with pytest.raises(SystemExit, match="unknown domain 'moon'"):
        bench.names("standard,moon", set(bench.DOMAINS), "domain", bench.DOMAIN_GROUPS)


def test_the_controller_list_comes_from_the_pipeline():
    known = bench.known_controllers()
    assert known is None or {"pid", "mpc"} <= known


def test_tuning_and_held_out_groups_cover_every_domain_once_and_all_runs_both():
    from ball_balance.sim.config import DOMAIN_SETS

    tuning = bench.names("tuning", set(bench.DOMAINS), "domain", bench.DOMAIN_GROUPS)
    held_out = bench.names("held_out", set(bench.DOMAINS), "domain", bench.DOMAIN_GROUPS)
    assert tuning == list(DOMAIN_SETS["tuning"]) and len(tuning) == 19
    assert held_out == list(DOMAIN_SETS["held_out"]) and not set(tuning) & set(held_out)
    assert sorted(bench.names("all", set(bench.DOMAINS), "domain", bench.DOMAIN_GROUPS)) == sorted(tuning + held_out)


def test_parameter_overrides_are_read_as_yaml_and_unknown_names_refused():
    assert bench.name_value("ki:=0.0", "--controller-param") == ("ki", 0.0)
    assert bench.name_value("estimate_input_gain:=false", "--tracker-param") == ("estimate_input_gain", False)
    with pytest.raises(SystemExit, match="expected NAME:=VALUE"):
        bench.name_value("ki=0", "--controller-param")
    schema = bench.controller_schema("pid")
    bench.check_names((("ki", 0.0),), schema, "--controller-param", "pid")
    with pytest.raises(SystemExit, match="nosuch is not a parameter of pid"):
        bench.check_names((("nosuch", 1),), schema, "--controller-param", "pid")
