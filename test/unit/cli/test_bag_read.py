"""Damaged MCAP bags: `bag info` and the reader `bag play` uses say in one line which file is
damaged, where and how, never a traceback, a KeyError or a play that stops early as if done."""
import random
import struct

import pytest
from mcap.reader import make_reader

from ball_balance.cli import main as cli_main
from ball_balance.cli.bag_read import BagDamaged, BagFile
from ball_balance.cli.errors import CliError
from ball_balance.cli.mcap_write import CHUNK, MESSAGE, McapWriter

COUNT = 79
START_NS = 1_700_000_000_000_000_000


def write_bag(folder, count: int = COUNT, chunk_size_bytes: int = 4096):
    """A bag as `bag record` writes it: /chatter with `count` std_msgs/String in several chunks."""
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    from ball_balance.cli.bag_format import message_definition

    folder.mkdir()
    path = folder / f"{folder.name}_0.mcap"
    with open(path, "wb") as stream:
        writer = McapWriter(stream, chunk_size_bytes)
        writer.start(profile="ros2", library="test")
        schema = writer.register_schema("std_msgs/msg/String", "ros2msg",
                                        message_definition("std_msgs/msg/String").encode())
        channel = writer.register_channel("/chatter", "cdr", schema, {"offered_qos_profiles": ""})
        for i in range(count):
            writer.add_message(channel, log_time=START_NS + i * 10_000_000, publish_time=START_NS + i * 10_000_000,
                               data=serialize_message(String(data=f"message {i} " * 4)), sequence=i)
        writer.add_metadata("rosbag2", {"serialized_metadata": "ros_distro: jazzy\n"})
        writer.finish()
    return path


def records(data: bytes):
    """(offset, opcode, end) of the top-level records, and of the records inside each chunk."""
    found, offset = [], 8
    while offset < len(data) - 8:
        opcode, length = struct.unpack_from("<BQ", data, offset)
        found.append((offset, opcode, offset + 9 + length))
        if opcode == CHUNK:
            (name_bytes,) = struct.unpack_from("<I", data, offset + 9 + 28)
            inner = offset + 9 + 32 + name_bytes + 8
            while inner < offset + 9 + length:
                inner_opcode, inner_length = struct.unpack_from("<BQ", data, inner)
                found.append((inner, inner_opcode, inner + 9 + inner_length))
                inner += 9 + inner_length
        offset += 9 + length
    return found


def damaged_copy(path, tmp_path, *changes):
    """A copy of the bag at path with bytes XOR-ed: changes are (offset, mask)."""
    data = bytearray(path.read_bytes())
    for offset, mask in changes:
        data[offset] ^= mask
    folder = tmp_path / "damaged"
    folder.mkdir(exist_ok=True)
    copy = folder / path.name
    copy.write_bytes(data)
    return copy


def info(capsys, path):
    code = cli_main.main(["bag", "info", str(path)])
    out, err = capsys.readouterr()
    return code, out, err


def play_all(path):
    with BagFile(str(path)) as bag:
        return list(bag.messages(set(bag.summary.channels)))


def test_an_intact_bag_reads_as_the_mcap_package_reads_it(tmp_path, capsys):
    path = write_bag(tmp_path / "run1")
    with open(path, "rb") as stream:
        expected = [(c.id, m.log_time, m.data) for _, c, m in make_reader(stream).iter_messages()]
    assert play_all(path) == expected and len(expected) == COUNT
    code, out, err = info(capsys, tmp_path / "run1")
    assert (code, err) == (0, "") and f"Messages:          {COUNT}\n" in out and "ROS Distro:        jazzy\n" in out


def second_chunk_messages(path):
    chunks = [r for r in records(path.read_bytes()) if r[1] == CHUNK]
    return [r for r in records(path.read_bytes()) if r[1] == MESSAGE and chunks[1][0] < r[0] < chunks[1][2]]


@pytest.mark.parametrize("what, change, expected", [
    ("a message's length", lambda m, d: (m[0] + 3, 0x10), "a record's length runs past the end of its chunk"),
    ("a message's channel", lambda m, d: (m[0] + 9, 77), "a message of channel 77, which the file does not hold"),
    ("a message's log time", lambda m, d: (m[0] + 9 + 2 + 4 + 3, 0x01), "do not match its message indexes"),
    ("the summary", lambda m, d: (len(d) - 200, 0x20), "the summary does not match its checksum"),
    ("the footer", lambda m, d: (len(d) - 8 - 20 + 2, 0x80), "the footer places the summary outside the file"),
])
def test_a_damaged_bag_is_one_line_naming_the_file_where_and_what(tmp_path, capsys, what, change, expected):
    path = write_bag(tmp_path / "run1")
    message = second_chunk_messages(path)[3]
    bad = damaged_copy(path, tmp_path, change(message, path.read_bytes()))
    code, out, err = info(capsys, bad.parent)
    assert code == 1 and out == "", what
    (line,) = err.splitlines()
    assert line.startswith(f"ros2py: {bad}: damaged") and expected in line, (what, line)
    with pytest.raises(BagDamaged, match=expected):
        play_all(bad)


def test_play_reads_up_to_the_damaged_chunk_then_says_so(tmp_path):
    path = write_bag(tmp_path / "run1")
    first_of_second_chunk = second_chunk_messages(path)[0]
    bad = damaged_copy(path, tmp_path, (first_of_second_chunk[0] + 3, 0x10))
    played = []
    with pytest.raises(BagDamaged, match=rf"damaged at byte {first_of_second_chunk[0]} \(a record's length"):
        with BagFile(str(bad)) as bag:
            for message in bag.messages(set(bag.summary.channels)):
                played.append(message)
    assert 0 < len(played) < COUNT  # the first chunk's messages, then the error: never a quiet end


def test_random_damage_is_one_line_or_a_bag_that_reads_whole_never_an_exception(tmp_path, capsys):
    path = write_bag(tmp_path / "run1")
    data = path.read_bytes()
    rng = random.Random(7)
    outcomes = set()
    for offset in rng.sample(range(len(data)), 150):
        bad = damaged_copy(path, tmp_path, (offset, rng.randrange(1, 256)))
        code, out, err = info(capsys, bad)
        if code == 0:  # a byte of a message's data or publish time: no checksum shows it
            assert err == "" and f"Messages:          {COUNT}\n" in out
            assert len(play_all(bad)) == COUNT
            outcomes.add("read whole")
            continue
        (line,) = err.splitlines()
        assert code == 1 and line.startswith("ros2py: ") and "ROS2PY_DEBUG" not in line, line
        outcomes.add("refused")
        try:
            played = play_all(bad)
        except CliError:
            continue
        assert len(played) == COUNT  # damage outside the chunks (schema, metadata): plays whole
    assert outcomes == {"read whole", "refused"}


@pytest.mark.parametrize("compression", ["ZSTD", "LZ4", "NONE"])
@pytest.mark.parametrize("chunked", [True, False])
def test_bags_of_other_writers_compressed_or_not_chunked_read_as_the_mcap_package_reads_them(
        tmp_path, compression, chunked):
    from mcap.writer import CompressionType, Writer

    path = tmp_path / "other.mcap"
    rng = random.Random(3)
    with open(path, "wb") as stream:
        writer = Writer(stream, compression=CompressionType[compression], use_chunking=chunked, chunk_size=2000)
        writer.start("ros2", "other writer")
        schema = writer.register_schema("std_msgs/msg/String", "ros2msg", b"string data")
        channels = [writer.register_channel(topic, "cdr", schema) for topic in ("/a", "/b")]
        for i in range(200):  # log times slightly out of order, as receive times can be
            writer.add_message(channels[i % 2], log_time=1000 + 10 * i + rng.randint(-30, 30), publish_time=0,
                               data=rng.randbytes(rng.randint(1, 80)), sequence=i)
        writer.finish()
    with open(path, "rb") as stream:
        expected = [(c.id, m.log_time, m.data) for _, c, m in make_reader(stream).iter_messages()]
    with BagFile(str(path)) as bag:
        bag.check()
        played = list(bag.messages(set(bag.summary.channels)))
        later = list(bag.messages({channels[1]}, first_ns=1500))
    if chunked:
        assert played == expected
        assert later == [m for m in expected if m[0] == channels[1] and m[1] >= 1500]
    else:  # without chunk indexes: in the file's order
        assert sorted(played) == sorted(expected)
