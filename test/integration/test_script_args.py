"""The scripts refuse bad command-line input with one line and exit code 2, before anything starts.

None of these tests starts a graph (the last one starts one and stops it at once): a refusal
comes from the scripts' own checks (scripts/lib/args.sh), in a second or two.
"""
import os
import re
import signal
import subprocess
import time

import pytest

from harness import ROOT

pytestmark = pytest.mark.integration


def run_script(launcher, script, *args, timeout=60):
    return launcher.run(["bash", str(ROOT / "scripts" / script), *args], timeout=timeout)


def assert_refused(result, line):
    assert (result.returncode, result.stderr.strip().splitlines()) == (2, [line]), result.stderr[-2000:]


@pytest.mark.parametrize("script, args, line", [
    ("sim_balance.sh", ["--controller"], "sim_balance.sh: --controller needs a value (see --help)"),
    ("sim_balance.sh", ["--ball", "0.1"], "sim_balance.sh: --ball needs 2 values (see --help)"),
    ("sim_balance.sh", ["--out", "--duration", "3"], "sim_balance.sh: --out needs a value (see --help)"),
    ("sim_pid.sh", ["--duration", "5", "--radius"], "sim_balance.sh: --radius needs a value (see --help)"),
    ("sim_arm.sh", ["--sim-config"], "sim_arm.sh: --sim-config needs a value (see --help)"),
    ("sim_policy_in_manager.sh", ["--params-file"],
     "sim_policy_in_manager.sh: --params-file needs a value (see --help)"),
    ("sim_policy_in_manager.sh", ["--ball", "0.1"], "sim_policy_in_manager.sh: --ball needs 2 values (see --help)"),
    ("run_demo.sh", ["--controller"], "run_demo.sh: --controller needs a value (see --help)"),
    ("tracker_usb.sh", ["--device"], "tracker_usb.sh: --device needs a value (see --help)"),
    ("real_ur.sh", ["--dry-run", "--max-home-distance"], "real_ur.sh: --max-home-distance needs a value (see --help)"),
])
def test_an_option_without_its_value_is_refused(launcher, script, args, line):
    # it ended on bash's `$2: unbound variable` (exit code 1)
    assert_refused(run_script(launcher, script, *args), line)


@pytest.mark.parametrize("script", ["setup.sh", "test.sh"])
def test_help_prints_the_usage_and_does_nothing_else(launcher, script):
    # --help ran the whole set-up (and rewrote env.sh); test.sh's also ran ruff
    result = run_script(launcher, script, "--help")
    assert result.returncode == 0 and result.stderr == "", result.stderr[-2000:]
    assert f"scripts/{script} --help" in result.stdout and "[setup]" not in result.stdout, result.stdout
    assert "[test]" not in result.stdout, result.stdout


@pytest.mark.parametrize("script, args, line", [
    ("setup.sh", ["--bogus"], "setup.sh: unknown argument '--bogus' (see --help)"),
    ("setup.sh", ["--force", "now"], "setup.sh: unknown argument 'now' (see --help)"),
])
def test_an_unknown_argument_to_setup_is_refused(launcher, script, args, line):
    assert_refused(run_script(launcher, script, *args), line)


@pytest.mark.parametrize("script", ["sim_balance.sh", "sim_policy_in_manager.sh", "run_demo.sh"])
def test_an_out_folder_that_cannot_be_made_is_refused(launcher, script):
    # the graph ran to its end, then the results were lost to a NotADirectoryError traceback
    assert_refused(run_script(launcher, script, "--out", "/dev/null/x"),
                   f"{script}: --out '/dev/null/x': cannot create the folder: Not a directory")


@pytest.mark.parametrize("script, port", [
    ("sim_balance.sh", "abc"), ("sim_pid.sh", "65536"), ("sim_policy_in_manager.sh", "-1"), ("run_demo.sh", "8o80"),
])
def test_a_live_view_port_that_is_not_a_port_is_refused(launcher, script, port):
    # it was accepted: the live view failed later and the run went on (exit code 0)
    name = script.replace("sim_pid", "sim_balance")
    assert_refused(run_script(launcher, script, "--live-view-port", port),
                   f"{name}: --live-view-port takes a port number 1-65535 (0: a free one), got '{port}'")


PARAMS_FILES = {  # content (None: no file), the checker's words
    "missing": (None, "cannot read parameter file '{}': No such file or directory"),
    "malformed": ("a: [1\n", "the parameters in '{}' are not valid YAML: expected ',' or ']', but got "
                             "'<stream end>' at line 2, column 1 (while parsing a flow sequence)"),
    "binary": (b"\x7fELF\x02\x01\x01\x00\xd0\xff", "cannot read parameter file '{}': not a UTF-8 text file "
                                                  "(byte 0xd0 at offset 8)"),
    "a list": ("- 1\n- 2\n", "parameter file '{}' must map node names to {{ros__parameters: {{...}}}}"),
}


def params_file(tmp_path, kind):
    content, words = PARAMS_FILES[kind]
    path = tmp_path / "params.yaml"
    if isinstance(content, bytes):
        path.write_bytes(content)
    elif content is not None:
        path.write_text(content)
    return path, words.format(path)


@pytest.mark.parametrize("kind", list(PARAMS_FILES))
def test_a_bad_params_file_is_refused(launcher, tmp_path, kind):
    # a Python traceback from the script's inline block
    path, words = params_file(tmp_path, kind)
    assert_refused(run_script(launcher, "sim_policy_in_manager.sh", "--params-file", str(path)),
                   f"sim_policy_in_manager.sh: --params-file: {words}")


@pytest.mark.parametrize("kind, args", [("missing", ["--check-params"]), ("malformed", ["--check-params"]),
                                        ("a list", [])])
def test_a_bad_controllers_file_is_refused(launcher, tmp_path, kind, args):
    # with --check-params it passed (exit code 0), and the start then failed
    path, words = params_file(tmp_path, kind)
    assert_refused(run_script(launcher, "sim_arm.sh", *args, "--controllers", str(path)),
                   f"sim_arm.sh: --controllers: {words}")


@pytest.mark.parametrize("script, args, line", [
    ("real_ur.sh", ["--dry-run", "--max-home-distance", "abc"],
     "real_ur.sh: --max-home-distance takes a number >= 0, got 'abc'"),
    # the tracker's options: real_ur.sh starts the tracker only after it has switched the controllers
    ("real_ur.sh", ["--dry-run", "--size", "640by480"], "real_ur.sh: --size '640by480' must be WIDTHxHEIGHT"),
    ("real_ur.sh", ["--dry-run", "--fps", "x"], "real_ur.sh: --fps takes a number >= 0, got 'x'"),
    ("tracker_usb.sh", ["--size", "0x480"], "tracker_usb.sh: --size '0x480' must be WIDTHxHEIGHT"),
    ("sim_arm.sh", ["--check-params", "--param", "camera_rate_hz"],
     "robot: --param takes NAME=VALUE, got 'camera_rate_hz'"),
])
def test_a_value_that_is_not_what_the_option_takes_is_refused(launcher, script, args, line):
    assert_refused(run_script(launcher, script, *args), line)


@pytest.mark.slow
@pytest.mark.parametrize("end", ["a core node dies", "Ctrl-C"])
def test_a_graph_ended_during_its_start_up_leaves_no_process_behind(launcher, end):
    # a core node dying: the live view's address announcer polled its log for up to 120 s in the
    # background, outliving the script (and holding its stderr: `sim_balance.sh ... | cat` did
    # not end). Ctrl-C: stop_all stopped what had started, then the script went on starting the
    # rest of the graph, and waited for it
    graph = launcher.start([str(ROOT / "scripts" / "sim_balance.sh"), "--truth-fed", "--live-view-port", "0"],
                           name="sim_balance")
    started = "started live_view_url" if end == "a core node dies" else "started controller"
    deadline = time.monotonic() + 45
    while started not in graph.output():
        assert graph.running and time.monotonic() < deadline, graph.output()[-3000:]
        time.sleep(0.1)
    if end == "a core node dies":  # before the live view has printed its address
        visualizer = int(re.search(r"started visualizer \(pid (\d+)\)", graph.output()).group(1))
        os.kill(visualizer, signal.SIGKILL)
    else:
        os.killpg(graph.popen.pid, signal.SIGINT)
    assert graph.wait(timeout=30) == (3 if end == "a core node dies" else 130), graph.output()[-3000:]
    deadline = time.monotonic() + 10
    while True:
        left = subprocess.run(["ps", "-s", str(graph.popen.pid), "-o", "pid=,stat=,args="],
                              capture_output=True, text=True)
        # zombies: ended, their parent (an ending process of the graph) not done reaping them yet
        running = [line for line in left.stdout.splitlines() if line.split()[1][0] != "Z"]
        if not running:
            break
        assert time.monotonic() < deadline, "left running after the script ended:\n" + "\n".join(running)
        time.sleep(0.2)


def test_an_optional_node_that_ends_is_reported_with_its_reason(tmp_path):
    # the live view with its port taken: the line said only "exited (status 2)"; the reason was in its log
    script = f"""
        set -euo pipefail
        source "{ROOT}/scripts/lib/stop_all.sh"; source "{ROOT}/scripts/lib/graph.sh"
        LOGS="{tmp_path}"
        start view optional bash -c 'echo "view: starting" >&2; echo "view: cannot start: port taken" >&2; exit 2'
        for _ in $(seq 100); do grep -q "graph goes on" "{tmp_path}/err" 2>/dev/null && break; sleep 0.1; done
        stop_all
    """
    with open(tmp_path / "err", "w") as err:
        subprocess.run(["bash", "-c", f"exec 3>&2; {script}"], stderr=err, timeout=60, check=True)
    lines = (tmp_path / "err").read_text().splitlines()
    assert "bash: bash exited (status 2: view: cannot start: port taken); the graph goes on without it" in lines, lines
