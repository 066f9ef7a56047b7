"""The keep-last-1 hand-over between a frame callback and the tracking thread."""
import threading

from ball_balance.vision.handover import LatestSlot


def test_the_taker_gets_the_newest_item_and_skipped_ones_are_counted():
    slot = LatestSlot()
    assert slot.put(1) is False
    assert slot.put(2) is True and slot.put(3) is True
    assert slot.take(0.0) == 3
    assert (slot.put_count, slot.replaced) == (3, 2)
    assert slot.take(0.0) is None                   # nothing new: nothing returned twice


def test_take_waits_for_a_put_from_another_thread():
    slot = LatestSlot()
    threading.Timer(0.05, slot.put, args=("frame",)).start()
    assert slot.take(timeout_s=30.0) == "frame"


def test_close_wakes_a_waiting_taker_for_good():
    slot = LatestSlot()
    result = []
    taker = threading.Thread(target=lambda: result.append(slot.take(timeout_s=30.0)))
    taker.start()
    slot.close()
    taker.join(timeout=30.0)
    assert result == [None] and slot.closed
    slot.put("late")
    assert slot.take(0.0) is None
