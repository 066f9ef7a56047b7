"""The Foxglove node's decisions without ROS: when to (re)subscribe, which frames to forward,
which topic lists to accept."""
import random
import struct

import pytest

from ball_balance import foxglove_relay as relay


def test_a_topic_is_subscribed_while_at_least_one_client_watches_it():
    watchers = relay.Watchers()
    assert watchers.joined(channel_id=1, client_id=10, latched=False) == relay.SUBSCRIBE
    assert watchers.joined(1, 11, latched=False) is None       # already subscribed
    assert watchers.joined(1, 11, latched=False) is None       # the same client again
    assert watchers.watching(1) == 2
    assert watchers.left(1, 10) is None
    assert watchers.left(1, 11) == relay.UNSUBSCRIBE
    assert watchers.left(1, 11) is None                        # unknown client: nothing to do
    assert watchers.left(2, 10) is None                        # unknown channel
    assert watchers.joined(1, 12, latched=False) == relay.SUBSCRIBE  # watched again


def test_any_says_whether_some_client_watches_something():
    watchers = relay.Watchers()
    assert not watchers.any
    watchers.joined(3, 1, latched=False)
    assert watchers.any
    watchers.left(3, 1)
    assert not watchers.any


def test_a_latched_topic_is_subscribed_anew_for_each_client_that_joins():
    watchers = relay.Watchers()
    assert watchers.joined(5, 1, latched=True) == relay.SUBSCRIBE
    assert watchers.joined(5, 2, latched=True) == relay.RESUBSCRIBE
    assert watchers.joined(5, 2, latched=True) is None
    assert watchers.left(5, 1) is None
    assert watchers.left(5, 2) == relay.UNSUBSCRIBE


def test_rate_limit_keeps_every_other_frame_of_a_jittery_stream_at_twice_the_rate():
    limit = relay.RateLimit(max_rate_hz=15.0)
    rng = random.Random(0)
    arrivals_ns = [round(k * 1e9 / 30 + rng.uniform(-3e6, 3e6)) for k in range(300)]  # 30 Hz, +-3 ms
    passed = [k for k, t in enumerate(arrivals_ns) if limit.allow(t)]
    assert passed == list(range(0, 300, 2))


def test_rate_limit_holds_the_rate_over_any_stretch():
    limit = relay.RateLimit(max_rate_hz=10.0)
    rng = random.Random(1)
    arrivals_ns = sorted(rng.randrange(0, 20 * 10**9) for _ in range(2000))  # 100 a second, at random
    passed = [t for t in arrivals_ns if limit.allow(t)]
    assert 190 <= len(passed) <= 201
    for start in range(0, 20 * 10**9, 10**8):  # every 1 s window: at most 10 (+1 at its edge)
        assert sum(start <= t < start + 10**9 for t in passed) <= 11
    assert min(b - a for a, b in zip(passed, passed[1:])) >= 75 * 10**6  # never closer than 3/4 of a period


def test_rate_limit_lets_one_message_of_a_burst_through():
    limit = relay.RateLimit(max_rate_hz=10.0)
    assert limit.allow(10**9) and not limit.allow(10**9) and not limit.allow(10**9 + 1000)
    assert limit.allow(2 * 10**9)  # after a gap, at once


def test_rate_limit_zero_lets_every_message_through():
    limit = relay.RateLimit(0.0)
    assert all(limit.allow(t) for t in (0, 0, 1, 1))


def test_images_are_the_rate_limited_types():
    assert relay.is_image("sensor_msgs/msg/Image") and relay.is_image("sensor_msgs/msg/CompressedImage")
    assert not relay.is_image("sensor_msgs/msg/CameraInfo") and not relay.is_image("ball_tracker_msgs/msg/BallState")


def test_topic_lists_must_be_absolute_names_each_once():
    assert relay.topic_list_problem(["/ball_state", "/tf"]) is None
    assert "at least one" in relay.topic_list_problem([])
    assert "'ball_state'" in relay.topic_list_problem(["ball_state"])
    assert "'/camera/'" in relay.topic_list_problem(["/camera/"])
    assert "/tf more than once" in relay.topic_list_problem(["/tf", "/ball_state", "/tf"])


def test_clock_time_is_read_from_either_byte_order():
    assert relay.clock_ns(b"\x00\x01\x00\x00" + struct.pack("<iI", 12, 500_000_000)) == 12_500_000_000
    assert relay.clock_ns(b"\x00\x00\x00\x00" + struct.pack(">iI", 3, 7)) == 3_000_000_007
    with pytest.raises(ValueError, match="not a serialized rosgraph_msgs/Clock"):
        relay.clock_ns(b"\x00\x01\x00\x00\x01")
    with pytest.raises(ValueError):
        relay.clock_ns(b"\x00\x10\x00\x00" + bytes(8))  # an XCDR2 encapsulation: not what rmw writes
