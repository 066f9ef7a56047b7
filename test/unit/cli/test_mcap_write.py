"""The recorder's MCAP writer, read back by the `mcap` package: by index and by scanning."""
import io

from mcap.reader import NonSeekingReader, SeekingReader

from ball_balance.cli.mcap_write import McapWriter

FRAME = bytes(range(256)) * 3600  # a camera frame's size: each one fills a chunk of its own


def write_bag(chunk_size_bytes=768 * 1024) -> io.BytesIO:
    stream = io.BytesIO()
    writer = McapWriter(stream, chunk_size_bytes)
    writer.start(profile="ros2", library="test")
    image_schema = writer.register_schema("sensor_msgs/msg/Image", "ros2msg", b"uint32 height")
    images = writer.register_channel("/camera/image_raw", "cdr", image_schema, {"offered_qos_profiles": ""})
    state_schema = writer.register_schema("ball_tracker_msgs/msg/BallState", "ros2msg", b"float64 x")
    states = writer.register_channel("/ball_state", "cdr", state_schema, {"topic_type_hash": "RIHS01_ab"})
    for i in range(5):
        writer.add_message(states, log_time=1000 + 10 * i, publish_time=990 + 10 * i, data=b"state%d" % i, sequence=i)
        writer.add_message(images, log_time=1005 + 10 * i, publish_time=1001 + 10 * i, data=FRAME, sequence=i)
    writer.add_message(states, log_time=2000, publish_time=2000, data=b"last", sequence=5)
    writer.add_metadata("rosbag2", {"serialized_metadata": "version: 9"})
    writer.finish()
    stream.seek(0)
    return stream


def test_indexed_reading_finds_every_message_in_time_order_with_its_channel_and_schema():
    reader = SeekingReader(write_bag(), validate_crcs=True)
    summary = reader.get_summary()
    assert summary.statistics.message_count == 11 and summary.statistics.channel_message_counts == {0: 5, 1: 6}
    assert (summary.statistics.message_start_time, summary.statistics.message_end_time) == (1000, 2000)
    assert len(summary.chunk_indexes) == 6  # five frames fill a chunk each; the last state is one more
    assert reader.get_header().profile == "ros2"
    messages = list(reader.iter_messages())
    assert [m.log_time for _, _, m in messages] == sorted(m.log_time for _, _, m in messages)
    schema, channel, message = messages[1]
    assert (schema.name, channel.topic, message.data, message.publish_time) == \
        ("sensor_msgs/msg/Image", "/camera/image_raw", FRAME, 1001)
    assert channel.metadata == {"offered_qos_profiles": ""}
    only_states = [m.data for _, _, m in reader.iter_messages(topics=["/ball_state"], starting_at=1020)]
    assert only_states == [b"state2", b"state3", b"state4", b"last"]
    (metadata,) = reader.iter_metadata()
    assert metadata.metadata == {"serialized_metadata": "version: 9"}


def test_a_scanning_reader_sees_the_same_messages_as_the_index():
    indexed = [(c.topic, m.sequence, m.data) for _, c, m in SeekingReader(write_bag()).iter_messages()]
    scanned = [(c.topic, m.sequence, m.data) for _, c, m in NonSeekingReader(write_bag()).iter_messages()]
    assert sorted(indexed) == sorted(scanned) and len(scanned) == 11


def test_small_messages_share_chunks_and_an_empty_recording_is_a_valid_file():
    reader = SeekingReader(write_bag(chunk_size_bytes=10 ** 9))
    assert len(reader.get_summary().chunk_indexes) == 1 and len(list(reader.iter_messages())) == 11

    stream = io.BytesIO()
    writer = McapWriter(stream)
    writer.start(profile="ros2", library="test")
    writer.finish()
    stream.seek(0)
    empty = SeekingReader(stream, validate_crcs=True)
    assert empty.get_summary().statistics.message_count == 0 and list(empty.iter_messages()) == []
