"""`ros2py control ...` against a controller manager stand-in serving canned responses."""
import re
import textwrap

import pytest

from harness import ROOT, executable, python_cmd

pytestmark = pytest.mark.integration

# A small controller manager: real controller_manager_msgs services, lifecycle bookkeeping only.
FAKE_CONTROLLER_MANAGER = textwrap.dedent("""
    import rclpy
    from controller_manager_msgs.msg import ControllerState, HardwareComponentState, HardwareInterface
    from controller_manager_msgs import srv
    from lifecycle_msgs.msg import State

    rclpy.init()
    node = rclpy.create_node('controller_manager')
    states = {'joint_state_broadcaster': 'active', 'plate_controller': 'inactive'}
    types = {'joint_state_broadcaster': 'joint_state_broadcaster/JointStateBroadcaster',
             'plate_controller': 'ball_balance/PlateController'}

    def list_controllers(request, response):
        for name, state in states.items():
            c = ControllerState(name=name, state=state, type=types.get(name, 'forward_command_controller/X'),
                                update_rate=500)
            if name == 'plate_controller':
                c.required_command_interfaces = ['joint1/velocity']
                c.claimed_interfaces = ['joint1/velocity'] if state == 'active' else []
            response.controller.append(c)
        return response

    def list_components(request, response):
        response.component = [HardwareComponentState(
            name='ur_arm', type='system', plugin_name='mock_components/GenericSystem',
            state=State(id=3, label='active'), rw_rate=250, is_async=True,
            command_interfaces=[HardwareInterface(name='joint1/velocity', data_type='double', is_available=True,
                                                  is_claimed=states['plate_controller'] == 'active')],
            state_interfaces=[HardwareInterface(name='joint1/position', data_type='double', is_available=True)])]
        return response

    def list_interfaces(request, response):
        response.command_interfaces = [HardwareInterface(name='joint1/velocity', data_type='double',
                                                         is_available=True),
                                       HardwareInterface(name='joint2/velocity', data_type='double',
                                                         is_available=False, is_claimed=True)]
        response.state_interfaces = [HardwareInterface(name='joint1/position', data_type='bool', is_available=True)]
        return response

    def load(request, response):
        response.ok = request.name not in states
        states.setdefault(request.name, 'unconfigured')
        return response

    def configure(request, response):
        response.ok = states.get(request.name) == 'unconfigured'
        if response.ok:
            states[request.name] = 'inactive'
        return response

    def unload(request, response):
        response.ok = states.get(request.name) in ('unconfigured', 'inactive')
        if response.ok:
            del states[request.name]
        return response

    def switch(request, response):
        bad = [n for n in request.activate_controllers if states.get(n) != 'inactive']
        bad += [n for n in request.deactivate_controllers if states.get(n) != 'active']
        if bad and request.strictness == srv.SwitchController.Request.STRICT:
            response.ok, response.message = False, 'cannot switch ' + ', '.join(bad)
            return response
        for n in request.deactivate_controllers:
            if states.get(n) == 'active':
                states[n] = 'inactive'
        for n in request.activate_controllers:
            if states.get(n) == 'inactive':
                states[n] = 'active'
        response.ok = True
        return response

    for name, kind, handler in [
            ('list_controllers', srv.ListControllers, list_controllers),
            ('list_hardware_components', srv.ListHardwareComponents, list_components),
            ('list_hardware_interfaces', srv.ListHardwareInterfaces, list_interfaces),
            ('load_controller', srv.LoadController, load),
            ('configure_controller', srv.ConfigureController, configure),
            ('unload_controller', srv.UnloadController, unload),
            ('switch_controller', srv.SwitchController, switch)]:
        node.create_service(kind, '~/' + name, handler)
    rclpy.spin(node)
""")


def ros2py(launcher, *args, timeout=30):
    return launcher.run(python_cmd("-m", "ball_balance.cli.main", *args), timeout=timeout)


@pytest.fixture
def manager(launcher, graph):
    launcher.start(python_cmd("-c", FAKE_CONTROLLER_MANAGER), name="controller_manager")
    graph.wait_for_service("/controller_manager/switch_controller", timeout=30)


def test_list_controllers_prints_aligned_name_type_state(launcher, manager):
    result = ros2py(launcher, "control", "list_controllers")
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines == [
        "joint_state_broadcaster joint_state_broadcaster/JointStateBroadcaster  active  ",
        "plate_controller        ball_balance/PlateController                   inactive",
    ]
    verbose = ros2py(launcher, "control", "list_controllers", "-v").stdout
    assert verbose.splitlines()[1:3] == ["\tupdate_rate: 500 Hz", "\tis_async: False"]
    assert "\trequired command interfaces:\n\t\tjoint1/velocity\n" in verbose
    assert "\texported reference interfaces:\n\texported state interfaces:\n" in verbose


def test_hardware_components_and_interfaces(launcher, manager):
    components = ros2py(launcher, "control", "list_hardware_components", "-v").stdout
    assert components.splitlines()[:7] == [
        "Hardware Component 1", "\tname: ur_arm", "\ttype: system",
        "\tplugin name: mock_components/GenericSystem", "\tstate: id=3 label=active",
        "\tread/write rate: 250 Hz", "\tis_async: True"]
    assert "\t\tjoint1/velocity [double] [available] [unclaimed]" in components
    assert "\tstate interfaces\n\t\tjoint1/position [double] [available]" in components
    interfaces = ros2py(launcher, "control", "list_hardware_interfaces").stdout
    # as ros2controlcli: an unavailable command interface is printed unclaimed
    assert interfaces == ("command interfaces\n\tjoint1/velocity [available] [unclaimed]\n"
                          "\tjoint2/velocity [unavailable] [unclaimed]\n"
                          "state interfaces\n\tjoint1/position\n")
    typed = ros2py(launcher, "control", "list_hardware_interfaces", "-v").stdout
    assert typed == ("command interfaces\n\tjoint1/velocity [double] [available] [unclaimed]\n"
                     "\tjoint2/velocity [double] [unavailable] [unclaimed]\n"
                     "state interfaces\n\tjoint1/position [bool]\n")


def test_controller_lifecycle_through_the_verbs(launcher, manager):
    switched = ros2py(launcher, "control", "switch_controllers", "--activate", "plate_controller", "--strict")
    assert (switched.returncode, switched.stdout) == (0, "Successfully switched controllers\n")
    listing = ros2py(launcher, "control", "list_controllers").stdout
    assert re.search(r"plate_controller\s+\S+\s+active", listing)

    refused = ros2py(launcher, "control", "switch_controllers", "--activate", "nope", "--strict")
    assert refused.returncode == 1
    assert refused.stderr.strip() == "ros2py: Error switching controllers: cannot switch nope"
    nothing = ros2py(launcher, "control", "switch_controllers", "--activate", "nope", "--best-effort")
    assert (nothing.returncode, nothing.stdout) == (1, "")
    assert nothing.stderr.strip() == "ros2py: switch changed nothing (activate nope: not done)"

    loaded = ros2py(launcher, "control", "load_controller", "extra", "--set-state", "active")
    assert loaded.stdout.splitlines() == ["Successfully loaded controller extra", "Successfully activated extra"]
    deactivated = ros2py(launcher, "control", "set_controller_state", "extra", "inactive")
    assert deactivated.stdout == "Successfully deactivated extra\n"
    unloaded = ros2py(launcher, "control", "unload_controller", "extra")
    assert (unloaded.returncode, unloaded.stdout) == (0, "Successfully unloaded controller extra\n")


def test_missing_controller_manager_is_one_line(launcher, ros_domain):
    result = ros2py(launcher, "control", "list_controllers", "-c", "/nobody", "--spin-time", "1")
    assert result.returncode == 1
    assert result.stderr.count("\n") == 1 and "controller manager '/nobody' not found" in result.stderr


def test_verbs_against_our_ros2_control_node(launcher, graph):
    launcher.start([executable("ros2_control_node"), "--ros-args", "--params-file",
                    str(ROOT / "config" / "ur_controllers.yaml"),
                    "-p", f"robot_description_file:={ROOT / 'config' / 'mock_ur.urdf'}"], name="ros2_control_node")
    graph.wait_for_service("/controller_manager/list_controllers", timeout=30)

    def states():
        lines = ros2py(launcher, "control", "list_controllers").stdout.splitlines()
        return {line.split()[0]: line.split()[-1] for line in lines if line.strip()}

    graph.spin_until(lambda: len(states()) == 3, 30, "the three configured controllers")
    assert states()["forward_position_controller"] == "active"
    swapped = ros2py(launcher, "control", "switch_controllers", "--deactivate", "forward_position_controller",
                     "--activate", "scaled_joint_trajectory_controller", "--strict")
    assert swapped.returncode == 0, swapped.stderr
    again = ros2py(launcher, "control", "switch_controllers", "--activate", "scaled_joint_trajectory_controller",
                   "--best-effort")
    assert again.returncode == 1 and again.stderr.startswith(
        "ros2py: switch changed nothing (activate scaled_joint_trajectory_controller: not done): "), again.stderr
    assert "already active" in again.stderr
    verbose = ros2py(launcher, "control", "list_controllers", "-v").stdout
    assert "scaled_joint_trajectory_controller" in verbose and "\tupdate_rate: 500 Hz\n\tis_async: False\n" in verbose
    components = ros2py(launcher, "control", "list_hardware_components", "-v").stdout
    assert "\tread/write rate: 500 Hz\n\tis_async: False\n" in components
    assert "\t\tshoulder_pan_joint/position [double] [available] [claimed]" in components
    after = states()
    assert (after["forward_position_controller"], after["scaled_joint_trajectory_controller"]) == \
        ("inactive", "active")
    interfaces = ros2py(launcher, "control", "list_hardware_interfaces").stdout
    assert "\tshoulder_pan_joint/position [available] [claimed]" in interfaces
    assert "state interfaces\n" in interfaces
    types = ros2py(launcher, "control", "list_controller_types").stdout
    assert "joint_state_broadcaster/JointStateBroadcaster" in types
    # the manager allows undeclared names for a spawner's <controller>.type and .params_file only
    typo = ros2py(launcher, "param", "set", "/controller_manager", "update_rat", "100")
    assert typo.returncode == 1 and typo.stderr.strip() == (
        "ros2py: Setting parameter failed: 'update_rat' is not a parameter of /controller_manager (did you mean "
        "update_rate?); a controller's own parameters are set on its node"), typo.stderr
    spawner_key = ros2py(launcher, "param", "set", "/controller_manager", "my_controller.type",
                         "position_controllers/JointGroupPositionController")
    assert spawner_key.returncode == 0, spawner_key.stderr
    hardware = ros2py(launcher, "control", "set_hardware_component_state", "mock_ur", "inactive")
    assert (hardware.returncode, hardware.stdout) == (0, "Successfully set mock_ur to state inactive\n")
    components = ros2py(launcher, "control", "list_hardware_components").stdout
    assert "\tname: mock_ur\n" in components and "\tstate: id=2 label=inactive\n" in components
