"""docs/parameters.md is generated from the parameter schemas (scripts/gen_param_docs.py): it
must match them, and the generator's --check must catch a stale file."""
import importlib.util
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "scripts" / "gen_param_docs.py"


@pytest.fixture(scope="module")
def gen():
    spec = importlib.util.spec_from_file_location("gen_param_docs", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclass looks its module up there
    try:
        spec.loader.exec_module(module)
        yield module
    finally:
        sys.modules.pop(spec.name, None)


def test_parameter_docs_are_up_to_date(gen, capsys):
    code = gen.main(["--check"])
    message = capsys.readouterr().err.strip()
    assert code == 0, f"{message}, and commit it (a parameter schema changed)"


def test_check_names_a_stale_file(gen, tmp_path, capsys):
    stale = tmp_path / "parameters.md"
    stale.write_text(gen.render().replace("| `kp` |", "| `kp_old` |"))
    assert gen.main(["--check", "--output", str(stale)]) == 1
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and str(stale) in lines[0] and gen.COMMAND in lines[0]
    assert gen.main(["--check", "--output", str(tmp_path / "missing.md")]) == 1
    assert "missing" in capsys.readouterr().err


def test_every_executable_and_plugin_is_accounted_for(gen):
    setup = gen._setup_dicts()
    documented = {c.executable or c.name for c in gen.components()} | set(gen.WITHOUT_SCHEMA)
    for group in ("EXECUTABLES", "CMPY_HARDWARE", "CMPY_CONTROLLERS"):
        assert set(setup[group]) <= documented, f"{group}: add it to NODES or WITHOUT_SCHEMA in {SCRIPT.name}"


def test_output_is_deterministic(gen):
    assert gen.render() == gen.render()


@pytest.mark.parametrize("node", ["ball_tracker", "ball_balance_controller", "ball_balance_mpc",
                                  "ball_balance_policy"])
def test_a_user_holds_at_most_15_settings_per_node(gen, node):
    """The tracker and each controller node mark the settings a user sets (user_facing); the
    rest are advanced, and the docs list them after."""
    component = next(c for c in gen.components() if c.kind == "node" and c.name == node)
    user = [p.name for p in component.schema() if p.user_facing]
    assert 1 <= len(user) <= 15, user
