"""control_msgs as authored here must be the upstream Jazzy types: same RIHS01 type hash.

The hashes below were published by a public build of control_msgs (generated
`*__description.c`, see docs/interface_provenance.md, section 5), not computed by us. rosidl
computes ours at build time into share/control_msgs/<kind>/<Type>.json; a field of a
different type, name or order changes the hash.

JointTrajectoryControllerState gained `speed_scaling_factor` in control_msgs 5.3 (Jazzy);
no public hash of that layout was found. The public hash of the earlier layout is tested
instead on our description with that one last field taken out, which checks every other
field (and every referenced type) against upstream.
"""
import copy

import pytest
from rosidl_generator_type_description import calculate_type_hash
from test_interface_hashes import type_description, type_hashes

BUILD = "generated rosidl_generator_c of a public control_msgs 5.x build (saahu27/aprs)"
UPSTREAM_JAZZY = {
    "control_msgs/action/FollowJointTrajectory":
        "RIHS01_738ebcb7a2d7cfa42f9f1001cc99ce3a4383d1cfe508015d9be8485e4b1c66f6",
    "control_msgs/action/FollowJointTrajectory_Goal":
        "RIHS01_8a9060704b269608f5a340934cc26e66869dd14bdac29e2e7fd9ec8b9882d205",
    "control_msgs/action/FollowJointTrajectory_Result":
        "RIHS01_8002e99ed2c14c6faa522f2a93c26d744c5982f254f9e98ff9c6f19789bdb220",
    "control_msgs/action/FollowJointTrajectory_Feedback":
        "RIHS01_3fd0aaecf71725121ae1ff7f01098a5e0da581e672be18a6b2c286cb43d96b49",
    "control_msgs/action/FollowJointTrajectory_SendGoal":
        "RIHS01_b13789dddc325a7a962825c45e28c77d37237ec129dd0c34dc5994562938c57f",
    "control_msgs/action/FollowJointTrajectory_GetResult":
        "RIHS01_e3ceb38e3e1867c8dc0f46014df26e90eb93422f27e9e97f936e07f94be4bc8b",
    "control_msgs/action/FollowJointTrajectory_FeedbackMessage":
        "RIHS01_80398fcb9674a79081a9906e2ccf0c804dd7cb15e22e362e606ee87186beab71",
    "control_msgs/msg/JointTolerance":
        "RIHS01_c254f9cece0f3b733017b6990fd46d1326e25242d6b8844398c97d9a88e7d648",
    "control_msgs/msg/JointComponentTolerance":
        "RIHS01_739ea7566931944d33830fa10f1bf5e7a7fbdc3172bce7a7eaac642bd6e3ffa4",
    "control_msgs/srv/QueryTrajectoryState":
        "RIHS01_4a0935dffef18bc5b9e101c9d03d84e681ecd4cebd724b8f11fde008751a325a",
    "control_msgs/srv/QueryTrajectoryState_Request":
        "RIHS01_ec3322824b7a1ee850e03ff951f48b10395cab62a5a5662da32000f8b06aa791",
    "control_msgs/srv/QueryTrajectoryState_Response":
        "RIHS01_f7b920129b8d5841312bcb89e6275508e19b3735a371b2df6e417447a44ea5db",
}
# control_msgs 4.x-5.2 JointTrajectoryControllerState (no speed_scaling_factor), same kind of build
STATE_BEFORE_SPEED_SCALING = "RIHS01_6cb9ac0858fc11b54bd6c0a46f032ea243c16856182276d8eb0875f6ce6a8335"
STATE = "control_msgs/msg/JointTrajectoryControllerState"


def owner(type_name: str) -> str:
    """The interface file whose JSON records `type_name` (an action's or service's parts live in it)."""
    package, kind, name = type_name.split("/")
    return f"{package}/{kind}/{name.split('_')[0]}"


@pytest.mark.parametrize("type_name", sorted(UPSTREAM_JAZZY))
def test_control_msgs_type_hash_equals_upstream_jazzy(type_name):
    assert type_hashes(owner(type_name))[type_name] == UPSTREAM_JAZZY[type_name], f"differs from upstream ({BUILD})"


def test_controller_state_is_upstream_with_speed_scaling_factor_appended():
    description = type_description(STATE)
    fields = description["type_description"]["fields"]
    assert fields[-1]["name"] == "speed_scaling_factor"
    assert fields[-1]["type"]["type_id"] == 11  # FIELD_TYPE_DOUBLE
    before = copy.deepcopy(description)
    before["type_description"]["fields"] = fields[:-1]
    assert calculate_type_hash(before) == STATE_BEFORE_SPEED_SCALING


@pytest.mark.parametrize("type_name", ["control_msgs/action/FollowJointTrajectory", STATE,
                                       "control_msgs/srv/QueryTrajectoryState"])
def test_referenced_types_hash_as_the_installed_jazzy_ones(type_name):
    """trajectory_msgs, geometry_msgs, std_msgs, ... as embedded here are the installed ones."""
    for referenced, hash_string in type_hashes(type_name).items():
        if not referenced.startswith("control_msgs/"):
            assert type_hashes(referenced)[referenced] == hash_string, referenced
