"""Publish a recorded session again at its original timing (the engine of ``replay``).

Each played topic gets a publisher of its recorded type with its recorded QoS (the first
offered profile), and the raw CDR bytes are published unchanged, so subscribers see exactly
what the bridge sent. The time line (record/player_state.py) says when each message is due:
at the recorded log time divided by the rate, unless paused, stepped, sped up or moved by a
seek. ``/clock`` (rosgraph_msgs/Clock) carries the bag time so that consumers can run with
``use_sim_time``. Other sinks (the Foxglove view) get every published record too; without a
node (``--no-ros``) they are the only ones. The lateness of every publication is kept, so the
benchmark can report the replay timing error.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from decimal import Decimal
from typing import TYPE_CHECKING, Any

from mcap.records import Message

from ssi_bridge.record.player_state import Action, PlayerState, select_topics, until_time
from ssi_bridge.record.reader import Bag

if TYPE_CHECKING:
    from rclpy.node import Node
    from rclpy.publisher import Publisher

logger = logging.getLogger(__name__)

#: a record sink: (recorded topic, MCAP message record)
Sink = Callable[[str, Message], None]


@dataclass
class ReplayOptions:
    """What ``replay`` was asked to do."""

    #: playback speed factor (2 = twice as fast)
    rate: float = 1.0
    loop: bool = False
    #: seconds into the bag where playback starts
    start_offset: float = 0.0
    #: topics to play (None: all, or those matched by ``regex``)
    topics: list[str] | None = None
    #: play the topics this regular expression finds (re.search), with ``topics``
    regex: str = ""
    #: topics not to play
    exclude_topics: list[str] = field(default_factory=list)
    #: do not play the topics this regular expression finds
    exclude_regex: str = ""
    #: recorded name -> published name
    remap: dict[str, str] = field(default_factory=dict)
    #: /clock rate in Hz (0: no /clock)
    clock_hz: float = 0.0
    #: wait (up to this many seconds) until every publisher has a subscriber (0: do not)
    wait_for_subscribers: float = 0.0
    #: bag seconds to play from the start offset (None: to the end)
    playback_duration: float | None = None
    #: stop after this time: a ROS time in s, or seconds from the bag start (None: the end)
    playback_until: float | Decimal | None = None
    #: ``playback_until`` is a ROS time whatever its value (not seconds from the start)
    until_is_ros_time: bool = False
    #: start with the time line paused (space, ~/resume or Foxglove starts it)
    start_paused: bool = False
    #: at the end, wait for a seek instead of returning (the Foxglove view keeps serving)
    hold_at_end: bool = False

    def __post_init__(self) -> None:
        if not self.rate > 0:
            raise ValueError(f"rate {self.rate}: must be > 0")
        if self.start_offset < 0:
            raise ValueError(f"start offset {self.start_offset}: must be >= 0")
        if self.clock_hz < 0:
            raise ValueError(f"clock rate {self.clock_hz}: must be >= 0")
        if self.wait_for_subscribers < 0:
            raise ValueError(f"wait for subscribers {self.wait_for_subscribers}: must be >= 0")
        for name in ("playback_duration", "playback_until"):
            value = getattr(self, name)
            if value is not None and value < 0:
                raise ValueError(f"{name.replace('_', ' ')} {value}: must be >= 0")


class Player:
    """Replays one bag through the publishers of ``node`` (None: only through ``sinks``).

    Raises RecordingError when the topic selection names a topic the bag lacks or leaves none.

    :param node: the node whose publishers replay the topics
    :param bag: the open bag
    :param options: topics, rate, start, end, loop, clock, remaps (``replay``'s options)
    :param sinks: more consumers of every published record (e.g. the Foxglove view)
    """

    def __init__(self, node: Node | None, bag: Bag, options: ReplayOptions,
                 sinks: list[Sink] | None = None) -> None:
        self.node, self.bag, self.options = node, bag, options
        self.topics = select_topics(bag.topics, options.topics, options.regex,
                                    options.exclude_topics, options.exclude_regex)
        start = bag.start_ns + int(options.start_offset * 1e9)
        self.state = PlayerState(bag.start_ns, bag.end_ns, start_ns=start, rate=options.rate,
                                 paused=options.start_paused,
                                 until_ns=until_time(start, bag.start_ns, options.playback_until,
                                                     options.playback_duration,
                                                     options.until_is_ros_time))
        self.sinks: list[Sink] = list(sinks or [])
        self.publishers: dict[str, Publisher] = {}
        self.clock_pub: Publisher | None = None
        if node is not None:
            self._create_publishers(node)
        #: publication lateness (s) of every message of the last pass (not the stepped ones)
        self.lateness: list[float] = []
        self.published = 0

    def _create_publishers(self, node: Node) -> None:
        from rclpy.qos import QoSProfile

        from ssi_bridge.record.qos import parse_qos
        from ssi_bridge.record.types import message_class

        for name in self.topics:
            recorded = self.bag.topics[name]
            profiles = parse_qos(recorded.qos_text)
            qos = profiles[0] if profiles else QoSProfile(depth=10)
            self.publishers[name] = node.create_publisher(
                message_class(recorded.type), self.options.remap.get(name, name), qos)
        if self.options.clock_hz > 0:
            from rosgraph_msgs.msg import Clock
            # rosbag2 publishes /clock with depth 1
            self.clock_pub = node.create_publisher(Clock, "/clock", QoSProfile(depth=1))
            self._clock_msg = Clock()

    def wait_for_subscribers(self) -> bool:
        """Block until each publisher is matched, or the configured timeout passes.

        Returns True when every topic has a subscriber; otherwise logs which ones have none
        and returns False (playback starts anyway).
        """
        began = time.monotonic()
        deadline = began + self.options.wait_for_subscribers
        while True:
            alone = [t for t, p in self.publishers.items() if p.get_subscription_count() == 0]
            if not alone or self.state.stopped:
                if not alone:
                    logger.info("every topic has a subscriber after %.2f s",
                                time.monotonic() - began)
                return not alone
            if time.monotonic() >= deadline:
                logger.info("no subscriber on %s after %.1f s; playing anyway",
                            ", ".join(alone), self.options.wait_for_subscribers)
                return False
            time.sleep(0.01)

    def wait_for_delivery(self, timeout_s: float = 2.0) -> bool:
        """Wait until reliable subscribers acknowledged everything (before the process ends).

        Without it the last messages of a replay can die with the publisher: DDS drops what a
        destroyed writer has not had acknowledged yet.

        :param timeout_s: longest wait (s)
        :returns: False when ``timeout_s`` passed first
        """
        from rclpy.duration import Duration

        deadline = Duration(nanoseconds=int(timeout_s * 1e9))
        return all(p.wait_for_all_acked(deadline) for p in self.publishers.values())

    def _publish_clock(self, bag_ns: int) -> None:
        """Publish /clock = ``bag_ns``."""
        assert self.clock_pub is not None
        self._clock_msg.clock.sec, self._clock_msg.clock.nanosec = divmod(bag_ns, 1_000_000_000)
        self.clock_pub.publish(self._clock_msg)

    def _publish(self, topic: str, record: Message) -> None:
        publisher = self.publishers.get(topic)
        if publisher is not None:
            publisher.publish(record.data)
        for sink in self.sinks:
            sink(topic, record)

    def play_once(self, progress: Callable[[], None] | None = None) -> int:
        """Play the bag (or its selected part) once; return the messages published.

        Follows the time line: waits while paused, reads the bag again after a seek, ends at
        the end time, after :meth:`PlayerState.stop`, or (with ``hold_at_end`` waiting for a
        seek) at the end of the bag. ``progress()`` is called about every 0.1 s.
        """
        state = self.state
        ticks = _Ticks(self, progress)
        count = 0
        self.lateness = []
        state.restart(state.seek_ns)
        while True:
            generation = state.generation
            records = self.bag.messages(self.topics, start_ns=state.seek_ns)
            action = Action.STOP
            for topic, record in records:
                while True:
                    action, wait = state.decide(record.log_time, generation)
                    if action is not Action.WAIT:
                        break
                    state.wait(ticks.run(wait))
                if action is not Action.PUBLISH:
                    break
                self._publish(topic, record)
                if wait is not None:
                    self.lateness.append(wait)
                state.played()
                count += 1
                ticks.run(None)  # /clock and the progress line also when nothing waits
            else:
                action = Action.STOP
            records.close()
            if action is Action.RESEEK:
                continue
            state.finish()
            if progress is not None:
                progress()
            self.published += count
            if (not state.stopped and self.options.hold_at_end
                    and state.wait_for_seek(state.generation, None)):
                count = 0
                continue
            return count

    def play(self, progress: Callable[[], None] | None = None) -> int:
        """Wait for subscribers, then play once, or forever with ``loop``; return the count.

        :param progress: called about every 0.1 s (the terminal's progress line)
        """
        if self.options.wait_for_subscribers > 0 and self.publishers:
            self.wait_for_subscribers()
        while True:
            self.play_once(progress)
            if not self.options.loop or self.state.stopped:
                if self.publishers:
                    self.wait_for_delivery()
                return self.published
            self.state.seek(self.state.start_ns)


class _Ticks:
    """The periodic work of the engine: /clock at its rate, the progress line every 0.1 s."""

    def __init__(self, player: Player, progress: Callable[[], None] | None) -> None:
        self.player, self.progress = player, progress
        hz = player.options.clock_hz if player.clock_pub is not None else 0.0
        self.clock_period = 1.0 / hz if hz > 0 else None
        self.next_clock = self.next_progress = time.monotonic()

    def run(self, wait: float | None) -> float:
        """Do what is due; return how long the engine may sleep (at most ``wait``, 0.25 s)."""
        now = time.monotonic()
        if self.clock_period is not None and now >= self.next_clock:
            self.player._publish_clock(self.player.state.snapshot().bag_ns)
            self.next_clock = max(self.next_clock + self.clock_period, now)
        if self.progress is not None and now >= self.next_progress:
            self.progress()
            self.next_progress = now + 0.1
        due = [t - now for t, on in ((self.next_progress, self.progress is not None),
                                     (self.next_clock, self.clock_period is not None)) if on]
        return max(0.0, min([0.25, *due, *([wait] if wait else [])]))
