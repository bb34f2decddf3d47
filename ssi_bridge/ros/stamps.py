"""``header.stamp`` of a cycle: the wire time of its SYNC as ROS time, strictly increasing.

ROS system time is wire time (``base/timebase.to_ros_ns``, no clock is read). With
``use_sim_time`` the offset sim - wire is taken from one bracketed pair of reads (a pair a
thread switch split is read again); before the first ``/clock`` there is no time to stamp
with: nothing is published and the node says so once. A stamp at or before the last one (the
clock stepped back, an NTP step) becomes last + 1 ns and is counted (bus diagnostics
``clock_steps``).
"""

from __future__ import annotations

from rclpy.clock import Clock, ROSClock

from ssi_bridge.base.timebase import to_ros_ns, wire_now
from ssi_bridge.ros.rclpy_compat import RcutilsLogger


class Stamper:
    """Stamps of one node's cycles.

    :param clock: the node's rclpy clock (a node's is a ``ROSClock``: with use_sim_time it
        follows ``/clock``, and the stamps with it)
    :param logger: the node's log (waiting for ``/clock``, and when it arrives)
    """

    def __init__(self, clock: Clock, logger: RcutilsLogger) -> None:
        self._clock = clock if isinstance(clock, ROSClock) else None
        self._logger = logger
        self._last_ns = 0
        self._waiting_for_clock = False
        #: header stamps moved forward because the clock stepped back (NTP step)
        self.clock_steps = 0

    def stamp_ns(self, wire_t: float) -> int | None:
        """ROS time (ns) of wire time ``wire_t``: strictly after the last stamp; None = wait."""
        stamp = to_ros_ns(wire_t)
        clock = self._clock
        if clock is not None and clock.ros_time_is_active:
            for _ in range(5):
                before = wire_now()
                sim_ns = clock.now().nanoseconds
                after = wire_now()
                if after - before < 1e-4:
                    break
            if sim_ns <= 0:
                if not self._waiting_for_clock:
                    self._waiting_for_clock = True
                    self._logger.warning(
                        "use_sim_time is true and no /clock has arrived: waiting for /clock, "
                        "nothing is published until it does")
                return None
            if self._waiting_for_clock:
                self._waiting_for_clock = False
                self._logger.info("/clock arrived: publishing")
            stamp += sim_ns - to_ros_ns(0.5 * (before + after))
            if stamp <= 0:
                return None
        if stamp <= self._last_ns:
            self.clock_steps += 1
            stamp = self._last_ns + 1
        self._last_ns = stamp
        return stamp


__all__ = ["Stamper"]
