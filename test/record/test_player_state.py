"""The replay's time line without ROS (record/player_state.py): pause, step, rate, seek, the
end time (until, duration) and rosbag2's topic selection, on a clock the test turns."""

from __future__ import annotations

import threading
import time

import pytest

from ssi_bridge.exceptions import RecordingError
from ssi_bridge.record.player_state import (NS, Action, PlayerState, select_topics,
                                            until_time)

T0 = 1_700_000_000 * NS
MS = 1_000_000


class Clock:
    """A monotonic clock that moves only when told."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def make(clock: Clock, **kw) -> PlayerState:  # type: ignore[no-untyped-def]
    return PlayerState(T0, T0 + 10 * NS, clock=clock, **kw)


def test_a_message_is_due_at_its_log_time_over_the_rate() -> None:
    clock = Clock()
    state = make(clock, rate=2.0)
    assert state.decide(T0, 0) == (Action.PUBLISH, 0.0)
    action, wait = state.decide(T0 + 1 * NS, 0)
    assert action is Action.WAIT and wait == pytest.approx(0.5)
    clock.now += 0.5
    assert state.decide(T0 + 1 * NS, 0)[0] is Action.PUBLISH
    clock.now += 0.25  # 0.25 s late: lateness reported, the schedule does not move
    action, late = state.decide(T0 + 1 * NS, 0)
    assert action is Action.PUBLISH and late == pytest.approx(0.25)
    assert state.decide(T0 + 2 * NS, 0)[1] == pytest.approx(0.25)


def test_pause_freezes_the_time_line_and_resume_continues_from_there() -> None:
    clock = Clock()
    state = make(clock)
    clock.now += 1.0
    assert state.pause() and not state.pause()
    clock.now += 5.0  # paused for 5 s: the bag time stays at 1 s
    assert state.snapshot().bag_ns == T0 + 1 * NS and state.snapshot().paused
    assert state.decide(T0 + 1 * NS + MS, 0) == (Action.WAIT, None)
    assert state.resume() and not state.resume()
    action, wait = state.decide(T0 + 2 * NS, 0)
    assert action is Action.WAIT and wait == pytest.approx(1.0)
    assert state.toggle() is True and state.toggle() is False


def test_step_publishes_one_message_while_paused_and_moves_the_time_line() -> None:
    clock = Clock()
    state = make(clock, paused=True)
    assert state.decide(T0 + 3 * NS, 0) == (Action.WAIT, None)
    assert state.step()
    assert state.decide(T0 + 3 * NS, 0) == (Action.PUBLISH, None)
    assert state.decide(T0 + 4 * NS, 0) == (Action.WAIT, None), "one step, one message"
    assert state.snapshot().bag_ns == T0 + 3 * NS
    state.resume()
    assert state.decide(T0 + 4 * NS, 0)[1] == pytest.approx(1.0)
    assert not state.step(), "a step needs a paused time line"


def test_set_rate_keeps_the_bag_time_reached() -> None:
    clock = Clock()
    state = make(clock)
    clock.now += 2.0
    state.set_rate(4.0)
    assert state.snapshot().bag_ns == T0 + 2 * NS
    assert state.decide(T0 + 6 * NS, 0)[1] == pytest.approx(1.0)
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="must be > 0"):
            state.set_rate(bad)
    assert state.rate == 4.0


def test_seek_restarts_the_reading_clamped_into_the_bag() -> None:
    clock = Clock()
    state = make(clock, paused=True)
    gen = state.generation
    assert state.seek(T0 + 5 * NS) == T0 + 5 * NS
    assert state.decide(T0 + 1 * NS, gen) == (Action.RESEEK, None)
    assert state.seek_ns == T0 + 5 * NS and state.paused, "a paused player stays paused"
    state.resume()
    assert state.decide(T0 + 5 * NS, state.generation)[0] is Action.PUBLISH
    assert state.seek(T0 + 99 * NS) == T0 + 10 * NS and state.seek(0) == T0


def test_until_stops_after_the_last_message_at_or_before_it() -> None:
    clock = Clock()
    state = make(clock, until_ns=T0 + 2 * NS)
    clock.now += 10
    assert state.decide(T0 + 2 * NS, 0)[0] is Action.PUBLISH
    assert state.decide(T0 + 2 * NS + 1, 0) == (Action.STOP, None)


def test_until_time_reads_ros_times_offsets_and_durations() -> None:
    start = T0 + 1 * NS
    assert until_time(start, T0) is None
    assert until_time(start, T0, until=2.5) == T0 + 2_500_000_000, "seconds from the start"
    assert until_time(start, T0, until=1_700_000_003.25) == T0 + 3_250_000_000, "a ROS time"
    assert until_time(start, T0, duration=2.0) == start + 2 * NS, "from the start offset"
    assert until_time(start, T0, until=1.0, duration=3.0) == start + 3 * NS, "the later one"
    assert until_time(start, T0, until=2.5, ros_time=True) == 2_500_000_000, "forced ROS time"
    with pytest.raises(ValueError):
        until_time(start, T0, duration=-1)


def test_stop_ends_a_wait_at_once_and_the_listeners_hear_every_change() -> None:
    state = PlayerState(T0, T0 + 10 * NS, paused=True)
    heard: list[str] = []
    state.on_change(heard.append)
    waiter = threading.Thread(target=state.wait, args=(30.0,))
    began = time.monotonic()
    waiter.start()
    state.resume(), state.pause(), state.set_rate(2.0), state.seek(T0)
    state.stop()
    waiter.join(5.0)
    assert time.monotonic() - began < 5.0
    assert heard == ["resume", "pause", "rate", "seek"]
    assert state.decide(T0, state.generation) == (Action.STOP, None)
    assert not state.wait_for_seek(state.generation, 5.0)


TOPICS = ["/diagnostics", "/joint_states", "/ssi_bridge/events", "/ssi_bridge/status"]


@pytest.mark.parametrize(("kw", "chosen"), [
    ({}, TOPICS),
    ({"topics": ["/joint_states"]}, ["/joint_states"]),
    ({"regex": "^/ssi_bridge/"}, ["/ssi_bridge/events", "/ssi_bridge/status"]),
    ({"topics": ["/diagnostics"], "regex": "status$"}, ["/diagnostics", "/ssi_bridge/status"]),
    ({"exclude_topics": ["/diagnostics"]}, TOPICS[1:]),
    # a name the bag lacks excludes nothing, as in ros2 bag play (rosbag2's storage filter)
    ({"exclude_topics": ["/nope", "/diagnostics"]}, TOPICS[1:]),
    ({"exclude_topics": ["/nope"]}, TOPICS),
    ({"exclude_regex": "ssi_bridge"}, ["/diagnostics", "/joint_states"]),
    ({"regex": "ssi_bridge", "exclude_regex": "events"}, ["/ssi_bridge/status"]),
])
def test_topic_selection_as_rosbag2(kw, chosen) -> None:  # type: ignore[no-untyped-def]
    assert select_topics(TOPICS, **kw) == chosen


@pytest.mark.parametrize(("kw", "match"), [
    ({"topics": ["/nope"]}, "no topic /nope"),
    ({"regex": "("}, "regular expression"),
    ({"exclude_regex": "."}, "leaves nothing to play"),
])
def test_topic_selection_refusals(kw, match: str) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(RecordingError, match=match):
        select_topics(TOPICS, **kw)
