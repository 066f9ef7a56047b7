"""Lock-step on a slower machine: the whole simulated graph (camera, tracker, PID, monitor) with
its rendering slowed to several times a frame period gives the monitor's figures of an
unslowed run, only later. Both graphs run at once on private domains, so each also has the
other's load. A controller node stepping on its own timer (the policy) keeps the pace too."""
import re
from pathlib import Path

import pytest

from harness import ROOT, DomainLease, Launcher

pytestmark = [pytest.mark.integration, pytest.mark.slow]

DURATION_S = 9.0
EXTRA_RENDER_S = 0.06   # each frame renders at least 60 ms: over three 16.7 ms frame periods


def metrics(folder: Path) -> dict:
    lines = (folder / "metrics.txt").read_text().splitlines()
    return {k: float(v) for k, v in (line.split(": ") for line in lines)}


@pytest.mark.timeout(900)
def test_slower_rendering_changes_how_long_the_run_takes_not_its_figures(tmp_path):
    leases = [DomainLease(), DomainLease()]
    launchers = [Launcher(lease.domain_id, tmp_path) for lease in leases]
    graphs = []
    try:
        for launcher, extra in zip(launchers, (0.0, EXTRA_RENDER_S), strict=True):
            out = tmp_path / f"render_plus_{extra:g}"
            cmd = [str(ROOT / "scripts" / "sim_balance.sh"), "--controller", "pid", "--duration", str(DURATION_S),
                   "--out", str(out), "--sim-param", f"camera_extra_render_s={extra}"]
            graphs.append((launcher.start(cmd, name=out.name), out))
        for graph, _ in graphs:
            assert graph.wait(timeout=800) == 0, graph.output()[-3000:]
    finally:
        for launcher in launchers:
            launcher.stop_all()
        for lease in leases:
            lease.release()
    quick, slowed = (metrics(out) for _, out in graphs)
    assert quick["drop"] == slowed["drop"] == 0
    assert abs(quick["rmse_steady_m"] - slowed["rmse_steady_m"]) <= 1e-3, (quick, slowed)
    assert abs(quick["settle_s"] - slowed["settle_s"]) <= 0.5, (quick, slowed)
    renders_ms = [float(ms) for ms in re.findall(r"a frame renders in ([0-9.]+) ms", sim_log(graphs[1][0].output()))]
    assert renders_ms and min(renders_ms) >= 1e3 * EXTRA_RENDER_S   # it was slowed, and said how fast it ran


@pytest.mark.timeout(900)
def test_a_controller_stepping_on_its_own_timer_is_answered_by_its_state(tmp_path):
    # the policy node steps at its next tick of simulated time, which a simulation waiting for
    # its /plate_cmd would never reach: the state's arrival answers the frame instead
    lease = DomainLease()
    launcher = Launcher(lease.domain_id, tmp_path)
    try:
        out = tmp_path / "policy"
        graph = launcher.start([str(ROOT / "scripts" / "sim_balance.sh"), "--controller", "policy", "--duration",
                                "4", "--out", str(out)], name=out.name)
        assert graph.wait(timeout=800) == 0, graph.output()[-3000:]
    finally:
        launcher.stop_all()
        lease.release()
    log = sim_log(graph.output())
    assert re.search(r"lock-step at t = [0-9.]+ s: [1-9][0-9]* frame\(s\) answered, 0 given up", log), log[-3000:]
    assert "never answered" not in log, log[-3000:]
    assert metrics(out)["drop"] == 0


def sim_log(script_output: str) -> str:
    match = re.search(r"logs in (\S*/ball_balance_graph\.\w+)", script_output)
    return (Path(match.group(1)) / "sim.log").read_text(errors="replace") if match else ""
