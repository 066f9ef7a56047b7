"""The live view in a real browser: Debian's Chromium, headless, driven over the DevTools
protocol (test/cdp_client.py), on the simulated graph as scripts/sim_balance.sh starts it (the
PID tracking a circle, so the ball keeps moving). The page loads from the node alone (nothing
from elsewhere), shows camera frames and the ball moving (values read from the page's DOM),
and sets a gain through the controller's parameters. By itself, with no robot manager, its
emergency stop button answers at once that there is none. With the robot manager (a graph
started for it), the page's buttons configure and activate the arm, and its emergency stop
button stops it as the joint states show.

Chromium comes from scripts/tools/install_test_browser.sh (scripts/test.sh runs it); without
it the tests are skipped.
"""
import time

import pytest
from cdp_client import Browser, browser_path
from rcl_interfaces.srv import GetParameters
from sensor_msgs.msg import JointState

from harness import ROOT, DomainLease, Graph, Launcher, executable

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.timeout(1200),
              pytest.mark.skipif(browser_path() is None,
                                 reason="needs Debian's chromium (scripts/tools/install_test_browser.sh)")]

# wall-clock deadlines, far above what they took on two cores with two busy loops beside
START_TIMEOUT_S = 240.0      # the graph up and the live view's address printed
PAGE_TIMEOUT_S = 60.0        # the page connected, a frame and ball states shown
# the graph up: sim_balance.sh brings the arm up through the robot manager, whose deadlines grow
# with the load (scripts/lib/graph.sh bring_up); seen 2-4 min on one core beside two busy loops
ENGAGE_TIMEOUT_S = 480.0
MOVING_TIMEOUT_S = 90.0      # the ball seen at places 10 mm apart (the simulation may run at 0.2x)
REPLY_TIMEOUT_S = 30.0       # a button's reply shown
STILL_RAD_S = 1e-3           # every joint slower than this after the emergency stop


def reply(browser) -> str:
    """The next reply the page shows (its status line once no request is waiting)."""
    return browser.wait_for("(() => { const t = document.getElementById('status-line').textContent;"
                            " return t.indexOf('waiting') < 0 && t !== '-' ? t : ''; })()",
                            REPLY_TIMEOUT_S, "a reply on the page")


class OwnDomain:
    """A launcher and a graph on a ROS domain of their own, and the page a browser opens there;
    `close()` closes the page (its last look kept for a failure) and stops every process."""

    def __init__(self, tmp_path_factory, name: str):
        self.lease = DomainLease()
        self.logs = tmp_path_factory.mktemp(name)
        self.launcher, self.graph = Launcher(self.lease.domain_id, self.logs), Graph(self.lease.domain_id)
        self.browser = None

    def open_page(self, url: str) -> Browser:
        self.browser = Browser(self.logs / "chromium.log")
        self.browser.open(url)
        return self.browser

    def open_live_view(self) -> Browser:
        """Start the live view on a free port beside the graph and open its page."""
        view = self.launcher.start([executable("ball_balance_live_view"), "--ros-args", "-p", "port:=0"],
                                   name="live_view")
        return self.open_page(self.graph.wait_for_output(view, r"live view on (http://127\.0\.0\.1:\d+/)",
                                                         START_TIMEOUT_S, "the live view's start-up line"))

    def close(self) -> None:
        if self.browser is not None:
            try:
                self.browser.screenshot(self.logs / "page.png")   # what the page showed last, for a failure
            except Exception:  # noqa: BLE001 - best effort
                pass
            self.browser.close()
        self.launcher.stop_all()
        self.graph.close()
        self.lease.release()


@pytest.fixture(scope="module")
def live(tmp_path_factory):
    domain = OwnDomain(tmp_path_factory, "live_view")
    try:
        sim = domain.launcher.start([str(ROOT / "scripts" / "sim_balance.sh"), "--controller", "pid", "--reference",
                                     "circle", "--radius", "0.06", "--period", "6", "--live-view-port", "0"],
                                    name="sim_balance")
        url = domain.graph.wait_for_output(sim, r"live view \(open it in a browser\): (http://127\.0\.0\.1:\d+/)",
                                           START_TIMEOUT_S, "the live view's address from sim_balance.sh")
        yield sim, domain.graph, domain.open_page(url)
    finally:
        domain.close()


def test_the_page_loads_and_shows_the_camera_and_the_ball_moving(live):
    sim, graph, browser = live
    browser.wait_for("document.getElementById('connection').textContent === 'connected'", PAGE_TIMEOUT_S,
                     "the page connected to the live view")
    # nothing but the node's own files: every resource the page loaded came from its origin
    origins = browser.evaluate("[...new Set(performance.getEntriesByType('resource')"
                               ".map(e => new URL(e.name).origin).concat([location.origin]))]")
    assert len(set(origins)) == 1, origins
    browser.wait_for("document.getElementById('controller-state').textContent.startsWith('engaged')",
                     ENGAGE_TIMEOUT_S, "the controller engaged on the page (the graph up)")
    browser.wait_for("parseInt(/(\\d+) sent/.exec(document.getElementById('image-info').textContent)[1]) >= 3",
                     PAGE_TIMEOUT_S, "camera frames on the page")
    seen, end = [], time.monotonic() + MOVING_TIMEOUT_S
    while time.monotonic() < end:
        x, y, count = browser.text("#ball-x"), browser.text("#ball-y"), browser.text("#ball-count")
        if x not in (None, "-") and y not in (None, "-"):
            seen.append((float(x), float(y), int(count)))
        spread = max(abs(a[i] - b[i]) for a in seen for b in seen for i in (0, 1)) if seen else 0.0
        if spread >= 10.0 and seen[-1][2] > seen[0][2]:
            break
        time.sleep(0.25)
    else:
        pytest.fail(f"the page did not show the ball moving in {MOVING_TIMEOUT_S:.0f} s: {seen[-10:]}")
    assert browser.text("#tracking") in ("tracking", "coasting")
    assert browser.text("#controller-state").startswith("engaged")
    assert sim.running, sim.output()[-3000:]


def test_a_gain_set_on_the_page_reaches_the_controller(live):
    sim, graph, browser = live
    browser.wait_for("document.getElementById('gain-kd') !== null", PAGE_TIMEOUT_S, "the gain fields")
    browser.evaluate("document.getElementById('gain-kd').value = '0.8'")
    browser.click("#btn-gains")
    assert reply(browser).startswith("OK: set "), browser.text("#status-line")
    response = graph.call(GetParameters, "/ball_balance_controller/get_parameters", GetParameters.Request(names=["kd"]),
                          timeout=60.0)
    assert response.values[0].double_value == pytest.approx(0.8)


@pytest.fixture(scope="module")
def alone(tmp_path_factory):
    """The live view by itself on a domain of its own: no robot manager, no graph."""
    domain = OwnDomain(tmp_path_factory, "live_view_alone")
    try:
        yield domain.open_live_view()
    finally:
        domain.close()


def test_without_a_robot_manager_the_emergency_stop_button_says_so_at_once(alone):
    browser = alone
    browser.wait_for("document.getElementById('connection').textContent === 'connected'", PAGE_TIMEOUT_S,
                     "the page connected to the live view")
    browser.wait_for("document.getElementById('rm-state').textContent.startsWith('absent')", PAGE_TIMEOUT_S,
                     "the page showing no robot manager")
    started = time.monotonic()
    browser.click("#btn-estop")
    text = reply(browser)
    assert text.startswith("FAILED: emergency stop: /robot_manager/emergency_stop is not available"), text
    assert time.monotonic() - started < REPLY_TIMEOUT_S
    assert browser.text("#rm-state").startswith("absent")


@pytest.fixture(scope="module")
def managed(tmp_path_factory):
    """The arm started for the robot manager (scripts/sim_arm.sh --managed: nothing that moves
    the arm active), the PID, the robot manager and the live view; the ball's state from the
    simulation's truth (no camera: the robot manager is told not to require one)."""
    domain = OwnDomain(tmp_path_factory, "live_view_managed")
    launcher = domain.launcher
    try:
        launcher.start([str(ROOT / "scripts" / "sim_arm.sh"), "--managed", "--sim-config",
                        str(ROOT / "config" / "sim_truth_fed.yaml"), "--param", "ball_x=0.05",
                        "--param", "ball_y=-0.03"], name="sim")
        launcher.start([executable("ball_balance_controller"), "--ros-args", "--params-file",
                        str(ROOT / "config" / "pid.yaml"), "-p", "use_sim_time:=true",
                        "-p", "joint_states_timeout_s:=5.0"], name="controller")
        launcher.start([executable("robot_manager"), "--ros-args", "-p", "camera_required:=false"],
                       name="robot_manager")
        yield domain.graph, domain.open_live_view()
    finally:
        domain.close()


def press(browser, button: str, label: str, expected_state: str) -> None:
    """Press a lifecycle button until the robot manager takes it (it may still be starting and
    refuse). A reply may be to an earlier press that was still under way, so a press whose
    reply is not the one hoped for may yet have taken: the page's state says."""
    shown = f"document.getElementById('rm-state').textContent === '{expected_state}'"
    deadline = time.monotonic() + START_TIMEOUT_S
    text = ""
    while not text.startswith(f"OK: {label}"):
        if browser.evaluate(shown):
            return
        assert time.monotonic() < deadline, f"{label} not taken within {START_TIMEOUT_S:.0f} s: {text}"
        browser.evaluate("document.getElementById('status-line').textContent = '-'")
        browser.click(button)
        text = reply(browser)
        if not text.startswith(f"OK: {label}"):
            time.sleep(2.0)
    browser.wait_for(shown, PAGE_TIMEOUT_S, f"the robot manager {expected_state} on the page")


def still(graph, what: str) -> None:
    """The joint states say the arm is still: every joint under 1e-3 rad/s, positions held."""
    states = graph.collect(JointState, "/joint_states", count=50, timeout=120.0)
    speeds = [max(abs(v) for v in msg.velocity) for msg in states if msg.velocity]
    assert speeds and max(speeds) < STILL_RAD_S, f"{what}: joint speeds {max(speeds or [0]):.5f} rad/s"
    moved = max(abs(a - b) for a, b in zip(states[0].position, states[-1].position, strict=True))
    assert moved < 1e-3, f"{what}: the arm moved {moved:.5f} rad"


def test_the_pages_buttons_bring_the_arm_up_and_its_emergency_stop_stops_it(managed):
    graph, browser = managed
    browser.wait_for("document.getElementById('rm-state').textContent === 'unconfigured'", START_TIMEOUT_S,
                     "the robot manager unconfigured on the page")
    press(browser, "#btn-configure", "configure", "inactive")
    press(browser, "#btn-activate", "activate", "active")
    browser.wait_for("document.getElementById('estop-state').textContent === 'released'", PAGE_TIMEOUT_S,
                     "the emergency stop released")
    browser.wait_for("document.getElementById('controller-state').textContent.startsWith('engaged')",
                     START_TIMEOUT_S, "the controller engaged")
    browser.click("#btn-estop")
    text = reply(browser)
    assert text.startswith("OK: emergency stop"), text
    still(graph, "after the emergency stop")
    browser.wait_for("document.getElementById('estop-state').textContent === 'ACTIVE'", PAGE_TIMEOUT_S,
                     "the page showing the emergency stop active")
    browser.wait_for("document.getElementById('events').textContent.indexOf('emergency') >= 0", PAGE_TIMEOUT_S,
                     "the emergency stop's event on the page")
    browser.evaluate("document.getElementById('status-line').textContent = '-'")
    browser.click("#btn-reset")
    assert reply(browser).startswith("OK: reset emergency stop"), browser.text("#status-line")
    browser.wait_for("document.getElementById('estop-state').textContent === 'released'", PAGE_TIMEOUT_S,
                     "the page showing the emergency stop released")
    still(graph, "after the reset")
