"""Our authored interfaces must be the upstream Jazzy types: same RIHS01 type hash.

The hashes below were published by upstream Jazzy builds (sources in the comments), not
computed by us. rosidl computes ours at build time into share/<pkg>/<kind>/<Type>.json; a
field of a different type, name or order changes the hash.
"""
import json
from pathlib import Path

import pytest
from ament_index_python.packages import get_package_share_directory

# type -> (RIHS01 hash published by a Jazzy build, where it was published)
UPSTREAM_JAZZY = {
    "tf2_msgs/msg/TFMessage": (
        "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087",
        "ZettaScaleLabs/zenoh-ros-examples rmw_zenoh/zenoh_sub.cxx (Jazzy rmw_zenoh key expression)"),
    "controller_manager_msgs/msg/ControllerState": (
        "RIHS01_9a8780ab9814b6032978a07c6c7033cf1a7894ac8d948a6fb72afea07b04cc83",
        "generated rosidl_generator_c of a Jazzy controller_manager_msgs 4.28+ build"),
    "controller_manager_msgs/msg/ChainConnection": (
        "RIHS01_2daecd1da4b171f48b291c79747657a651eb1ab8821b68e38b1c88c736bba91c", "same build"),
    "controller_manager_msgs/msg/NamedLifecycleState": (
        "RIHS01_b7947b6f8df8f7e93d1cb8d115842fb0eeddfa6fb5c7b86cc0f3cafd55be4c1f", "same build"),
    "controller_manager_msgs/msg/ControllerManagerActivity": (
        "RIHS01_35b7de5d611b6780e89732de325f2f765eacdb8a7adfe5821a27af4a03a7c244", "same build"),
    "controller_manager_msgs/srv/ListControllers": (
        "RIHS01_4f8e36bb1fa5afdeba45c2d56ae6a2097b1493a253f961dd6290c085033bd189", "same build"),
    "controller_manager_msgs/srv/SwitchController": (
        "RIHS01_d4ad10aa5da7808bc522d55d4123d8ef79de73d049d165639d7663ac37cc9895", "same build"),
    "controller_manager_msgs/srv/UnloadController": (
        "RIHS01_4055728e84c041348648d7f808c6681562000e3a9ce9fbb42c3350df25773f16",
        "generated type description of a Jazzy build"),
    "controller_manager_msgs/msg/HardwareInterface": (
        "RIHS01_b4c556991db81ca56a49338b5e8f0675a6707faee54fba161d2bbd4d963d418a",
        "generated type description of a Jazzy 4.31+ build (with data_type)"),
}


def _type_json(type_name: str) -> dict:
    package, kind, name = type_name.split("/")
    return json.loads((Path(get_package_share_directory(package)) / kind / f"{name}.json").read_text())


def type_hashes(type_name: str) -> dict:
    """All hashes rosidl recorded for `type_name` (itself and the types it references)."""
    return {entry["type_name"]: entry["hash_string"] for entry in _type_json(type_name)["type_hashes"]}


def type_description(type_name: str) -> dict:
    """The type description rosidl hashed for `type_name` (with referenced_type_descriptions)."""
    return _type_json(type_name)["type_description_msg"]


@pytest.mark.parametrize("type_name", sorted(UPSTREAM_JAZZY))
def test_authored_type_hash_equals_upstream_jazzy(type_name):
    expected, source = UPSTREAM_JAZZY[type_name]
    assert type_hashes(type_name)[type_name] == expected, f"differs from upstream ({source})"


@pytest.mark.parametrize("type_name", ["tf2_msgs/msg/TFMessage", "pal_statistics_msgs/msg/Statistics",
                                       "ball_tracker_msgs/msg/BallState"])
def test_referenced_standard_types_hash_as_the_installed_ones(type_name):
    """The std/geometry types our messages embed are the installed Jazzy ones, unchanged."""
    for referenced, hash_string in type_hashes(type_name).items():
        if referenced.split("/")[0] in ("std_msgs", "geometry_msgs", "builtin_interfaces"):
            assert type_hashes(referenced)[referenced] == hash_string, referenced
