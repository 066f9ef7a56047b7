"""What rosbag2 (Jazzy, metadata version 9) writes into an MCAP bag, without ROS: schema text,
QoS profiles, the bag's metadata, and reading them back (the files' records: bag_read.py).

- profile `ros2`; one schema per type, named `pkg/msg/Type`, encoding `ros2msg`, holding the
  .msg text followed by every nested type's text after a line of 80 '=' and `MSG: pkg/Type`;
- one channel per topic, message encoding `cdr`, metadata `offered_qos_profiles` (a YAML list
  of the publishers' QoS profiles, policies as names since version 9) and `topic_type_hash`
  (REP-2011, `RIHS01_...`);
- messages as the publisher's CDR bytes, log time = receive time, publish time = the
  publisher's source timestamp (ns since the epoch);
- a metadata record `rosbag2` whose `serialized_metadata` is the bag's metadata (the reader
  takes the version from it), and beside the file a `metadata.yaml` holding the same under
  `rosbag2_bagfile_information`.
"""
from __future__ import annotations

import os
import re
from typing import Dict, List, Optional

from ball_balance.cli.errors import CliError
from ball_balance.cli.messages import split_type_name
from ball_balance.cli.run import prefixes

METADATA_VERSION = 9  # rosbag2 Jazzy
PRIMITIVES = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
              "int32", "uint32", "int64", "uint64", "string", "wstring"}
SEPARATOR = "=" * 80


# --- message definitions (schema text) --------------------------------------------------
def msg_file_text(package: str, name: str) -> str:
    for prefix in prefixes():
        path = os.path.join(prefix, "share", package, "msg", f"{name}.msg")
        if os.path.isfile(path):
            with open(path, encoding="utf-8") as handle:
                return handle.read()
    raise CliError(f"cannot find the definition of {package}/msg/{name} (no {name}.msg in AMENT_PREFIX_PATH)")


def nested_type_of(line: str, package: str) -> Optional[str]:
    """'pkg/Type' for a .msg line declaring a field of a non-primitive type, else None."""
    code = line.split("#", 1)[0].strip()
    if not code or code == "---" or re.match(r"\S+\s+\w+\s*=", code):  # blank, separator, constant
        return None
    base = code.split()[0].split("[", 1)[0].split("<=", 1)[0]
    if base in PRIMITIVES:
        return None
    if "/" in base:
        parts = base.split("/")
        return f"{parts[0]}/{parts[-1]}"
    return "std_msgs/Header" if base == "Header" else f"{package}/{base}"


def nested_types(text: str, package: str) -> List[str]:
    """'pkg/Type' of every non-primitive field in a .msg text, in order of appearance."""
    found = []
    for line in text.splitlines():
        full = nested_type_of(line, package)
        if full and full not in found:
            found.append(full)
    return found


def message_definition(type_name: str) -> str:
    """The full ros2msg schema text of a message type, dependencies appended."""
    package, _, name = split_type_name(type_name)
    root = msg_file_text(package, name)
    text, queue, seen = root, nested_types(root, package), set()
    while queue:
        dependency = queue.pop(0)
        if dependency in seen:
            continue
        seen.add(dependency)
        dep_package, dep_name = dependency.split("/")
        dep_text = msg_file_text(dep_package, dep_name)
        text += f"\n{SEPARATOR}\nMSG: {dependency}\n{dep_text}"
        queue.extend(d for d in nested_types(dep_text, dep_package) if d not in seen)
    return text


# --- QoS profiles as rosbag2 records them -------------------------------------------------
# rmw's enum values (rmw/types.h) and the names rmw_qos_*_policy_to_str gives them
HISTORY = {0: "system_default", 1: "keep_last", 2: "keep_all", 3: "unknown"}
RELIABILITY = {0: "system_default", 1: "reliable", 2: "best_effort", 3: "unknown", 4: "best_available"}
DURABILITY = {0: "system_default", 1: "transient_local", 2: "volatile", 3: "unknown", 4: "best_available"}
LIVELINESS = {0: "system_default", 1: "automatic", 3: "manual_by_topic", 4: "unknown", 5: "best_available"}
INFINITE = {"sec": 9223372036, "nsec": 854775807}  # RMW_DURATION_INFINITE


def _duration(ns: int) -> Dict[str, int]:
    if ns <= 0 or ns >= 0x7FFFFFFFFFFFFFFF - 1:  # 0 (unset) and infinite are both recorded as infinite
        return dict(INFINITE)
    sec, nsec = divmod(int(ns), 1_000_000_000)
    return {"sec": sec, "nsec": nsec}


def qos_profile(history: int, depth: int, reliability: int, durability: int, deadline_ns: int, lifespan_ns: int,
                liveliness: int, lease_ns: int) -> dict:
    """One offered QoS profile as rosbag2 (version 9) writes it."""
    return {"history": HISTORY.get(history, "unknown"), "depth": int(depth),
            "reliability": RELIABILITY.get(reliability, "unknown"),
            "durability": DURABILITY.get(durability, "unknown"),
            "deadline": _duration(deadline_ns), "lifespan": _duration(lifespan_ns),
            "liveliness": LIVELINESS.get(liveliness, "unknown"),
            "liveliness_lease_duration": _duration(lease_ns), "avoid_ros_namespace_conventions": False}


def policy_name(value, names: Dict[int, str]) -> str:
    """A recorded policy (a name since version 9, an integer before) as its name."""
    if isinstance(value, int) and not isinstance(value, bool):
        return names.get(value, "unknown")
    return str(value)


def parse_offered_qos(text: str) -> List[dict]:
    """A channel's `offered_qos_profiles` metadata (YAML list; empty text: none)."""
    import yaml

    if not text.strip():
        return []
    try:
        profiles = yaml.safe_load(text)
    except yaml.YAMLError:
        return []
    return [p for p in profiles if isinstance(p, dict)] if isinstance(profiles, list) else []


def dump_yaml(data) -> str:
    import yaml

    return yaml.safe_dump(data, sort_keys=False, width=10 ** 9)


# --- the bag's metadata -------------------------------------------------------------------
def bag_metadata(file_name: str, topics: List[dict], counts: List[int], start_ns: int, duration_ns: int,
                 distro: str = "jazzy") -> dict:
    """rosbag2's BagMetadata (version 9) for one MCAP file.

    topics: {name, type, serialization_format, offered_qos_profiles (list), type_description_hash}."""
    total = sum(counts)
    return {
        "version": METADATA_VERSION, "storage_identifier": "mcap",
        "duration": {"nanoseconds": int(duration_ns)}, "starting_time": {"nanoseconds_since_epoch": int(start_ns)},
        "message_count": total,
        "topics_with_message_count": [{"topic_metadata": t, "message_count": n}
                                      for t, n in zip(topics, counts, strict=True)],
        "compression_format": "", "compression_mode": "",
        "relative_file_paths": [file_name],
        "files": [{"path": file_name, "starting_time": {"nanoseconds_since_epoch": int(start_ns)},
                   "duration": {"nanoseconds": int(duration_ns)}, "message_count": total}],
        "custom_data": {}, "ros_distro": distro,
    }


def mcap_files(path: str) -> List[str]:
    """The .mcap files of a bag folder (or the file itself); CliError when there are none."""
    if os.path.isdir(path):
        files = sorted(os.path.join(path, f) for f in os.listdir(path) if f.endswith(".mcap"))
        if not files:
            raise CliError(f"no .mcap file in bag folder '{path}'")
        return files
    if not os.path.isfile(path):
        raise CliError(f"bag '{path}' does not exist")
    return [path]


def ros_distro_of(metadata_records) -> str:
    """The ROS distribution from an MCAP's 'rosbag2' metadata record (or the older ROS_DISTRO key)."""
    import yaml

    for record in metadata_records:
        if record.name != "rosbag2":
            continue
        if record.metadata.get("ROS_DISTRO"):
            return record.metadata["ROS_DISTRO"]
        try:
            data = yaml.safe_load(record.metadata.get("serialized_metadata", "")) or {}
        except yaml.YAMLError:
            continue
        if isinstance(data, dict) and data.get("ros_distro"):
            return str(data["ros_distro"])
    return ""
