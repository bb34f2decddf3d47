"""The node's cycle: SYNC on the cycle thread, joint_states published where the cycle completes.

:class:`CyclePublisher` is a part of :class:`~ssi_bridge.ros.node.SsiBridgeNode` (it uses the
node's publishers, cycle core, stamper and settings). The cycle thread
(``ros/cycle.CycleThread``) sends each SYNC and keeps the pace. A cycle is complete when its
last expected TPDO arrives; the receive thread that handled that frame decides the cycle and
publishes ``joint_states`` at once, at its own (real-time) priority
(``client/cycle_gate.CycleGate``): no thread wakes up between the data and ``publish()``. The
cycle thread is woken once that publish returned. A cycle that does not complete within its
wait (``ros/cycle.cycle_waits``) is decided and published by the cycle thread at the timeout,
as before. Either way the cycle core decides with the same rules (``core/cycle.py``), and the
next SYNC goes out only after the cycle was published. The rest of a cycle (the health of the
SYNC before, ``~/events``, ``~/status``, recording, diagnostics on a level change) is done by
the cycle thread right after its next SYNC, while that SYNC's TPDOs are on the wire, and
before it hands that cycle to the receive thread: each cycle's messages still go out in
order, and the time from one SYNC to the next holds only the wire and joint_states. (Doing it
at once, when half a period was left, brought a level change a period sooner but measured no
cheaper, and at 8 joints dearer for the receive thread: docs/node.md, "The cycle thread and
prompt diagnostics".) The last cycle is finished when the cycle thread ends. Listen-only, the observer thread publishes each
observed cycle whole.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Any

from sensor_msgs.msg import JointState

from ssi_bridge.client.cycle_feed import sync_number
from ssi_bridge.client.listener import ObservedCycle
from ssi_bridge.core.cycle import CycleResult
from ssi_bridge.ros.cycle import cycle_waits
from ssi_bridge.ros.messages import JointStates, status_msg
from ssi_bridge.ros.rclpy_compat import RCLError

logger = logging.getLogger(__name__)

#: ``~/status``'s readers are counted (an rclpy call) once per this many seconds of cycles,
#: not each cycle: a reader DDS has matched gets its first ``~/status`` at most this long
#: after (plus a cycle), and a cycle after its last reader left may still build one
STATUS_READERS_EVERY_S = 0.05


@dataclass(slots=True)
class PublishedCycle:
    """A cycle whose ``joint_states`` is out: what the rest of the cycle needs."""

    result: CycleResult
    joint_state: JointState
    stamp_ns: int


class CyclePublisher:
    """The cycle of the node (see the module docstring).

    :param node: the ``SsiBridgeNode`` whose cycle this is (not imported: it imports this
        module; its parts are read each cycle: the bus side
        and the publishers are made again when the node is configured again)
    """

    def __init__(self, node: Any) -> None:
        self.node = node
        #: (wire time, number) of the SYNC the cycle thread armed for the receive thread
        self._armed = (0.0, 0)
        #: the cycle the receive thread published, for the cycle thread to finish
        self._handed: PublishedCycle | None = None
        #: the cycle published last, finished after the next SYNC went out
        self._pending: PublishedCycle | None = None
        #: joint_states, one message filled each cycle (a cycle is finished before the next
        #: one is decided, so nothing holds the one before when it is filled again)
        self._joint_states = JointStates()
        #: ~/status's publisher and its reader count, counted again from ``_readers_due``
        #: on (time.monotonic(): :data:`STATUS_READERS_EVERY_S` after the last count, at any
        #: SYNC rate: listen-only, the cycles are another master's)
        self._status_pub: Any = None
        self._status_readers = 0
        self._readers_due = 0.0
        #: the rclpy context has been shut down (its ``on_shutdown``; asked each cycle
        #: instead of ``context.ok()``, which takes two locks)
        self._shut_down = False
        node.context.on_shutdown(self._on_shutdown)

    def _on_shutdown(self) -> None:
        """The node's rclpy context was shut down (its ``on_shutdown`` callback)."""
        self._shut_down = True

    def _context_gone(self) -> bool:
        """Whether the context is no longer valid, noted for the next cycles: rclpy's own
        signal handler invalidates a context without its ``on_shutdown`` callbacks, so an
        rclpy error is where such a shutdown shows first."""
        if not self.node.context.ok():
            self._shut_down = True
        return self._shut_down

    # -- the master's cycle (cycle thread, receive thread) ---------------------------------
    def on_cycle(self) -> None:
        """One cycle; a shutdown racing it (the context goes first) ends it quietly."""
        if self._shut_down:
            return
        try:
            self._cycle()
        except RCLError:
            if not self._context_gone():
                raise

    def _cycle(self) -> None:
        """SYNC; the rest of the cycle before (:meth:`_finish`) while this one's TPDOs are on
        the wire; this cycle is published by the receive thread as its last TPDO arrives, or
        here once the wait for it is over."""
        node = self.node
        faults = node.bridge.faults
        if faults is not None and faults.active:
            for done in faults.expire():
                node.handlers.log_event("inject_fault", done.joint, f"expired {done.kind.name}",
                                        True, "fault duration over, cleared")
        client, master = node.client, node.master
        t_sync = client.sync()  # the master's one SYNC: every station's cycle
        self._finish_pending()  # nothing is armed yet: the receive thread decides nothing
        # the TPDOs need their wire time (cycle.cycle_waits); a late cycle skips SYNC slots,
        # counted in cycles_missed, instead of sending SYNCs nobody can answer. The master
        # wakes once every station's cycle is complete and its publish (if handed) ended.
        assert master is not None
        seq = sync_number(client, t_sync)
        self._armed = (t_sync, seq)
        self._handed = None
        node.cycle_core.prepare(seq)  # off the path from the last TPDO to publish()
        period = 1.0 / node.settings.publish_rate
        if master.gate.arm(self._on_complete):
            # mine False: the receive thread took it (and has finished)
            mine = master.wait_claim(*cycle_waits(period, node.cycle_wire_s))
        else:  # complete already (nothing to wait for): published here
            mine = True
        if mine:
            node._cycle_times.append(time.monotonic())  # the achieved rate: an interval
            self._pending = self._publish(*self._armed)
        else:
            self._pending, self._handed = self._handed, None
        # the bus load's queued frames, counted here with time to spare until the next SYNC
        # (client/load.py): not on the receive thread, not on the way to the SYNC
        master.load.count_queued()

    def _finish_pending(self) -> None:
        """Finish the cycle published last (:meth:`_finish`); an error is logged, and the
        cycle goes on."""
        pending, self._pending = self._pending, None
        if pending is None:
            return
        try:
            self._finish(pending)
        except RCLError:
            if not self._context_gone():
                logger.exception("finishing the cycle failed; continuing with the next one")
        except Exception:  # noqa: BLE001 - the next cycle's SYNC is out: it must be armed
            logger.exception("finishing the cycle failed; continuing with the next one")

    def on_end(self) -> None:
        """The cycle thread's last act (``CycleThread`` ``end``): finish the last cycle."""
        self._finish_pending()

    def _on_complete(self) -> None:
        """The receive thread: the armed cycle's last TPDO arrived; publish it now.

        An error is logged and the receive path goes on (it is no frame's fault); the cycle
        thread then finishes nothing of this cycle. A shutdown racing it (the context goes
        first) ends it quietly: the context is asked only then, not each cycle (an rclpy
        call with two locks, on the path to the next frame)."""
        node = self.node
        node._cycle_times.append(time.monotonic())  # the achieved rate: an interval
        try:
            self._handed = self._publish(*self._armed)
        except Exception:  # noqa: BLE001 - the receive thread must outlive one bad cycle
            if not self._context_gone():
                logger.exception("publishing the cycle failed; continuing with the next one")

    # -- listen-only (observer thread) -----------------------------------------------------
    def on_observed(self, cycle: ObservedCycle) -> None:
        """Publish the cycle of a SYNC another master (or the log) sent."""
        node = self.node
        if self._shut_down:
            return
        node._cycle_times.append(time.monotonic())  # the achieved rate is the observed one
        try:
            self.publish(cycle.sync_time, cycle.seq)
        except RCLError:
            if not self._context_gone():
                raise

    # -- one cycle ---------------------------------------------------------------------------
    def publish(self, t_sync: float, seq: int) -> None:
        """Publish joint_states and ~/status of the cycle latched at ``t_sync`` (wire time),
        SYNC number ``seq``, in one go."""
        published = self._publish(t_sync, seq)
        if published is not None:
            self._finish(published)

    def _publish(self, t_sync: float, seq: int) -> PublishedCycle | None:
        """Decide the cycle and publish its joint_states (None: nothing more to do, the stamp
        or the context is gone).

        The cycle core decides every joint (core/cycle.py); a joint it sets aside is left out
        of joint_states (and says why in ~/status), and a cycle with no joint to publish sends
        no joint_states.
        """
        node = self.node
        stamp_ns = node.stamper.stamp_ns(t_sync)
        if stamp_ns is None:
            return None
        # the health of the SYNC before, which nothing published depends on: in _finish
        core = node.cycle_core
        result = core.run(seq, t_sync, settle=False)
        handed = False
        try:
            js = self._joint_states.fill(result, stamp_ns, node.settings.frame_id)
            if js.name:
                if not node.publish_safe(node.joint_pub, js):
                    self._shut_down = True  # the context is gone (publish_safe)
                    return None
                probe = node._span_probe
                if probe is not None:  # bench/bench_node.py: the driver's own span
                    rx = getattr(node.client, "bus", None)  # listen-only: none
                    probe.published(getattr(rx, "rx_latest", 0.0), len(js.name))
            handed = True
            return PublishedCycle(result, js, stamp_ns)
        finally:
            if not handed:  # no _finish for this cycle: its health is judged all the same
                core.settle(result)

    def _finish(self, cycle: PublishedCycle) -> None:
        """The rest of a published cycle: the health of the SYNC before (``Cycle.settle``),
        recording, ``~/events`` of the frame checks,
        ``~/status`` (built only for a listener), diagnostics on a level change."""
        node = self.node
        result, js, stamp_ns = cycle.result, cycle.joint_state, cycle.stamp_ns
        node.cycle_core.settle(result)
        recorder = node.recorder
        capturing = recorder.capturing  # else record() keeps nothing: no topic name to ask
        if capturing and js.name:
            recorder.record(node.joint_pub.topic_name, js, stamp_ns)
        for part in result.joints:
            out = part.output
            if out is not None and out.events:
                for ok, text in out.events:
                    node.handlers.log_event("encoder_status", part.joint.name, "frame check",
                                            ok, text)
        # ~/status costs as much as the rest of the cycle: build it only for a listener
        status_pub = node.status_pub
        if capturing or self._status_read(status_pub) or node.liveview.wants(status_pub):
            status = status_msg(result, js.header)
            if status.channels and node.publish_safe(status_pub, status):
                recorder.record(status_pub.topic_name, status, stamp_ns)
        node._publish_on_change()

    def _status_read(self, status_pub: Any) -> bool:
        """Whether ``~/status`` has a DDS reader, as counted at most
        :data:`STATUS_READERS_EVERY_S` ago (at once for a publisher made anew)."""
        now = time.monotonic()
        if now >= self._readers_due or status_pub is not self._status_pub:
            self._status_pub = status_pub
            self._readers_due = now + STATUS_READERS_EVERY_S
            self._status_readers = status_pub.get_subscription_count()
        return self._status_readers > 0


__all__ = ["CyclePublisher", "PublishedCycle"]
