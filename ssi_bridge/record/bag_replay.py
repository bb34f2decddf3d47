"""Publish a recorded session again at its original timing (the engine of ``replay``).

Each recorded topic gets a publisher of its recorded type with its recorded QoS (the first
offered profile), and the raw CDR bytes are published unchanged, so subscribers see exactly
what the bridge sent. Message ``k`` is published at ``t_start + (log_time_k - t0) / rate`` on
the monotonic clock; ``/clock`` (rosgraph_msgs/Clock) carries the bag time so that consumers
can run with ``use_sim_time``. The lateness of every publication is kept, so the benchmark
can report the replay timing error.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import QoSProfile

from ssi_bridge.exceptions import RecordingError
from ssi_bridge.record.qos import parse_qos
from ssi_bridge.record.reader import Bag
from ssi_bridge.record.types import message_class

logger = logging.getLogger(__name__)

#: QoS of /clock as rosbag2 publishes it
CLOCK_QOS = QoSProfile(depth=1)


@dataclass
class ReplayOptions:
    """What ``replay`` was asked to do."""

    #: playback speed factor (2 = twice as fast)
    rate: float = 1.0
    loop: bool = False
    #: seconds into the bag where playback starts
    start_offset: float = 0.0
    #: topics to play (None: all)
    topics: list[str] | None = None
    #: recorded name -> published name
    remap: dict[str, str] = field(default_factory=dict)
    #: /clock rate in Hz (0: no /clock)
    clock_hz: float = 0.0
    #: wait (up to this many seconds) until every publisher has a subscriber
    wait_for_subscribers: float = 0.0

    def __post_init__(self) -> None:
        if not self.rate > 0:
            raise ValueError(f"rate {self.rate}: must be > 0")
        if self.start_offset < 0:
            raise ValueError(f"start offset {self.start_offset}: must be >= 0")
        if self.clock_hz < 0:
            raise ValueError(f"clock rate {self.clock_hz}: must be >= 0")


class Player:
    """Replays one bag through the publishers of ``node``."""

    def __init__(self, node: Node, bag: Bag, options: ReplayOptions) -> None:
        self.node, self.bag, self.options = node, bag, options
        topics = options.topics if options.topics is not None else list(bag.topics)
        unknown = [t for t in topics if t not in bag.topics]
        if unknown:
            raise RecordingError(f"{bag.path}: no topic {', '.join(unknown)} in the bag "
                                 f"(it has {', '.join(sorted(bag.topics))})")
        self.publishers: dict[str, Any] = {}
        for name in topics:
            recorded = bag.topics[name]
            profiles = parse_qos(recorded.qos_text)
            qos = profiles[0] if profiles else QoSProfile(depth=10)
            self.publishers[name] = node.create_publisher(
                message_class(recorded.type), options.remap.get(name, name), qos)
        self.clock_pub = None
        if options.clock_hz > 0:
            from rosgraph_msgs.msg import Clock
            self.clock_pub = node.create_publisher(Clock, "/clock", CLOCK_QOS)
            self._clock_msg = Clock()
        #: publication lateness (s) of every message of the last pass
        self.lateness: list[float] = []
        self.published = 0

    def wait_for_subscribers(self) -> None:
        """Block until each publisher is matched, or the configured timeout passes."""
        deadline = time.monotonic() + self.options.wait_for_subscribers
        while time.monotonic() < deadline:
            if all(p.get_subscription_count() > 0 for p in self.publishers.values()):
                return
            time.sleep(0.01)
        logger.warning("not every replayed topic has a subscriber; playing anyway")

    def wait_for_delivery(self, timeout_s: float = 2.0) -> bool:
        """Wait until reliable subscribers acknowledged everything (before the process ends).

        Without it the last messages of a replay can die with the publisher: DDS drops what a
        destroyed writer has not had acknowledged yet.
        """
        deadline = Duration(nanoseconds=int(timeout_s * 1e9))
        return all(p.wait_for_all_acked(deadline) for p in self.publishers.values())

    def _publish_clock(self, bag_ns: int) -> None:
        """Publish /clock = ``bag_ns``."""
        assert self.clock_pub is not None
        self._clock_msg.clock.sec, self._clock_msg.clock.nanosec = divmod(bag_ns, 1_000_000_000)
        self.clock_pub.publish(self._clock_msg)

    def play_once(self, progress: Callable[[float, float], None] | None = None) -> int:
        """Play the bag (or its selected part) once; return the messages published."""
        opts = self.options
        t0 = self.bag.start_ns + int(opts.start_offset * 1e9)
        total = max(0.0, (self.bag.end_ns - t0) / 1e9)
        start = time.monotonic()
        clock_period = 1.0 / opts.clock_hz if opts.clock_hz > 0 else None
        next_clock = start
        next_progress = start
        count = 0
        self.lateness = []
        for topic, record in self.bag.messages(list(self.publishers), start_ns=t0):
            target = start + (record.log_time - t0) / 1e9 / opts.rate
            while True:
                now = time.monotonic()
                if clock_period is not None and next_clock <= min(now, target):
                    self._publish_clock(t0 + int((next_clock - start) * opts.rate * 1e9))
                    next_clock += clock_period
                    continue
                wake = target if clock_period is None else min(target, next_clock)
                if now >= target:
                    break
                time.sleep(min(wake - now, 0.05))
            self.publishers[topic].publish(record.data)
            self.lateness.append(time.monotonic() - target)
            count += 1
            if progress is not None and now >= next_progress:
                progress((record.log_time - t0) / 1e9, total)
                next_progress = now + 0.1
        if progress is not None:
            progress(total, total)
        self.published += count
        return count

    def play(self, progress: Callable[[float, float], None] | None = None) -> int:
        """Play once, or forever with ``loop``; return the messages published."""
        if self.options.wait_for_subscribers > 0:
            self.wait_for_subscribers()
        while True:
            self.play_once(progress)
            if not self.options.loop:
                self.wait_for_delivery()
                return self.published
