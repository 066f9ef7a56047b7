"""What `control switch_controllers` reports, judged from the states before and after."""
from ball_balance.cli.control import switch_outcome


def test_a_switch_reports_done_and_skipped_parts():
    before = {"a": "inactive", "b": "active", "c": "active"}
    after = {"a": "active", "b": "inactive", "c": "active"}
    assert switch_outcome(before, after, ["a"], ["b"]) == (["deactivate b", "activate a"], [])
    assert switch_outcome(before, before, ["a", "nope"], []) == ([], ["activate a", "activate nope"])
    assert switch_outcome(after, after, ["a"], ["c"]) == ([], ["deactivate c", "activate a"])


def test_restarting_a_controller_counts_as_done():
    states = {"c": "active"}
    assert switch_outcome(states, states, ["c"], ["c"]) == (["deactivate c", "activate c"], [])
