"""One cycle of the bridge, ROS-free: for each joint, publish a vouched sample or set it aside.

The node's cycle thread sends SYNC ``seq`` at wire time ``t_sync``, waits for the TPDOs and
calls :meth:`Cycle.run`. For every joint the station's frame log
(:class:`~ssi_bridge.core.cycle_log.StationLog`) says whether the joint's sample is the
encoder's position at ``t_sync`` (rules in ``core/cycle_log.py``); the joint's core (``core/joint.py``) turns a vouched sample into
position and velocity, and counts one that is set aside as a stale cycle. The result says
per joint what to publish (or that it is left out, and why): the ROS layer only turns it into
messages. No joint is ever published under a stamp its sample was not latched at (docs/node.md,
"Which cycle a TPDO answers").
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from ssi_bridge.core.cycle_log import Answer, StationLog, VouchedSample
from ssi_bridge.core.joint import Joint, JointOutput


@dataclass(slots=True)  # read-only by convention: frozen would cost 2x per instance
class JointCycle:
    """One joint's share of one cycle."""

    joint: Joint
    #: what is published (None: the joint is left out of this cycle's message)
    output: JointOutput | None
    #: the vouched sample (None when set aside)
    sample: VouchedSample | None
    #: why the joint is left out ("" when published)
    reason: str
    #: the newest image of this SYNC's window, vouched or not (b"": none), for ``~/status``
    image: bytes


@dataclass
class CycleResult:
    """One cycle: the SYNC, and each joint's share in the configured order."""

    seq: int
    t_sync: float
    joints: list[JointCycle] = field(default_factory=list)

    @property
    def published(self) -> list[JointCycle]:
        """The joints with a sample latched at ``t_sync`` (the message's joints)."""
        return [j for j in self.joints if j.output is not None]


class Cycle:
    """The cycle decisions of every joint of a bridge.

    :param joints: the joints' cores by name, in the configured order (the dict is read each
        cycle: the node refills it when the bus side is opened again)
    :param logs: the frame log of each station by node id (read each cycle, like ``joints``)
    """

    def __init__(self, joints: Mapping[str, Joint], logs: Mapping[int, StationLog]) -> None:
        self.joints = joints
        self.logs = logs
        #: cycles in which at least one joint was set aside
        self.incomplete_cycles = 0

    def prepare(self, seq: int) -> None:
        """Have every station's frame log ask rule 3 for SYNC ``seq`` now, while its answers
        are on the wire (``StationLog.prepare``): :meth:`run` then finds it asked."""
        for log in {id(log): log for log in self.logs.values()}.values():
            log.prepare(seq)

    def run(self, seq: int, t_sync: float, *, settle: bool = True) -> CycleResult:
        """Decide SYNC ``seq`` (wire time ``t_sync``) for every joint.

        Each joint's counters and health take the cycle whether it is published or not.
        ``settle`` False leaves the health of the SYNC before (which nothing published
        depends on) to :meth:`settle`, for a caller that publishes first.
        """
        result = CycleResult(seq, t_sync)
        append = result.joints.append
        logs = self.logs
        # one pass over each station's slots: its frame log answers for all of them at once
        answers: dict[int, dict[int, Answer]] = {}
        incomplete = False
        for joint in self.joints.values():
            log = logs.get(joint.settings.station)
            if log is None:
                joint.leave_out("no frame log for the joint's station")
                append(JointCycle(joint, None, None, "no frame log", b""))
                incomplete = True
                continue
            by_slot = answers.get(id(log))
            if by_slot is None:
                slots = log.slots
                by_slot = answers[id(log)] = dict(zip(slots, log.answers(slots, seq)))
            sample, reason, _missing, image, position = (by_slot.get(joint.slot)
                                                         or log.answers((joint.slot,), seq)[0])
            if sample is None:  # set aside: a stale cycle, left out of the message
                joint.leave_out(reason, image, position)
                append(JointCycle(joint, None, None, reason, image))
                incomplete = True
                continue
            # latched at t_sync: its latch time is the stamp
            value = sample.position
            joint.count(t_sync, image, value, t_sync)
            append(JointCycle(joint, joint.output(t_sync, image, value, t_sync), sample, "",
                              image))
        if incomplete:
            self.incomplete_cycles += 1
        if settle:
            self.settle(result)
        return result

    def settle(self, result: CycleResult) -> None:
        """The health of the SYNC before ``result``'s, judged now that its window is over
        (``StationLog.settled``): every joint of a cycle :meth:`run` with ``settle`` False."""
        seq = result.seq
        logs = self.logs
        # per station: its slots' health inputs, asked once for all of them (None: no log)
        settled: dict[int, tuple[StationLog, dict[int, tuple[float, float] | None]] | None] = {}
        for part in result.joints:
            joint = part.joint
            station = joint.settings.station
            if station in settled:
                of_station = settled[station]
            else:
                log = logs.get(station)
                of_station = settled[station] = None if log is None else (
                    log, dict(zip(log.slots, log.settled_all(log.slots, seq - 1))))
            if of_station is None:
                joint.settle(seq, None)
                continue
            log, by_slot = of_station
            slot = joint.slot
            joint.settle(seq, by_slot[slot] if slot in by_slot else log.settled(slot, seq - 1))

__all__ = ["Cycle", "CycleResult", "JointCycle"]
