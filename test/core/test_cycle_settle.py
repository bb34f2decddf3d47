"""Cycle.run(settle=False) then Cycle.settle: the same joints as the one-step cycle.

The node publishes joint_states before the health of the SYNC before is judged (nothing
published depends on it, ``core/cycle.py``). Two identical sets of joints on one frame log,
fed the same cycles (vouched, partial, silent, late, implausible jumps): one as the cycle
decided each joint in one step (``settled(seq - 1)`` asked first, then ``Joint.update`` or
``Joint.set_aside`` with it: :func:`_one_step`), one by ``Cycle.run(settle=False)`` and
``Cycle.settle``, and one by ``Cycle.run``. Every output, counter and health figure must be
the same each cycle.
"""

from __future__ import annotations

import dataclasses
import math
import random

from ssi_bridge.core.cycle import Cycle
from ssi_bridge.core.cycle_log import StationLog
from ssi_bridge.core.joint import Joint
from ssi_bridge.protocol.images import encode_input
from ssi_bridge.protocol.registers import Reg
from ssi_bridge.protocol.settings import JointSettings

PERIOD = 0.002
SLOTS = 3


def _joints() -> dict[str, Joint]:
    return {f"j{s}": Joint(JointSettings(name=f"j{s}", slot=s), velocity_window=3,
                           max_speed=5.0, stale_cycles=3) for s in range(1, SLOTS + 1)}


def _state(joint: Joint) -> tuple:
    h = joint.health
    return (dataclasses.astuple(joint.counters), joint.position, h.level,
            h.lost_in_window, h.syncs_in_window, h.jumps_in_window)


def _one_step(joint: Joint, log: StationLog, seq: int, t: float) -> tuple[str, object]:
    """A joint's cycle as decided in one step: (reason, output or None)."""
    settled = log.settled(joint.slot, seq - 1)
    verdict = log.verdict(joint.slot, seq)
    sample = verdict.sample
    if sample is None:
        joint.set_aside(seq, settled, verdict.reason, verdict.image, verdict.position)
        return verdict.reason, None
    joint.count(t, sample.process_input, sample.position, t)
    return "", joint.update(t, sample.process_input, sample.position, t, seq=seq,
                            settled=settled)


def _same(a: float, b: float) -> bool:
    return a == b or (math.isnan(a) and math.isnan(b))


def test_settling_after_publishing_changes_nothing() -> None:
    rng = random.Random(7)
    log = StationLog(latch_bound=0.0008, slots=tuple(range(1, SLOTS + 1)))
    one, two, three = _joints(), _joints(), _joints()
    split, at_once = Cycle(two, {0: log}), Cycle(three, {0: log})
    for j in (*one.values(), *two.values(), *three.values()):
        j.settings = dataclasses.replace(j.settings, station=0)
    for k in range(1, 400):
        t = k * PERIOD
        log.sync(k, t)
        for slot in range(1, SLOTS + 1):
            pos = 40 * k * slot + (5000 if rng.random() < 0.02 else 0)  # now and then a jump
            image = encode_input(pos & 0xFFFFFF, int(Reg.REG_SSI_FRAME), False, False, False,
                                 0, 0, 0)
            r = rng.random()
            if r < 0.05:
                continue  # silent
            late = 0.002 if r < 0.08 else 0.0
            log.image(slot, t + 0.0002 + late, image, k)
            if r < 0.12:
                continue  # partial
            log.position(slot, t + 0.0003 + late, pos)
        reference = [_one_step(j, log, k, t) for j in one.values()]
        b = split.run(k, t, settle=False)
        split.settle(b)
        c = at_once.run(k, t)
        for (reason, out), ja, pb, pc in zip(reference, one.values(), b.joints, c.joints):
            for part in (pb, pc):
                assert part.reason == reason
                assert (part.output is None) == (out is None)
                if out is not None and part.output is not None:
                    assert _same(part.output.position, out.position)
                    assert _same(part.output.velocity, out.velocity)
                    assert part.output.events == out.events
                assert _state(part.joint) == _state(ja), (k, ja.name)
    assert at_once.incomplete_cycles == split.incomplete_cycles > 0
    assert sum(j.counters.samples for j in one.values()) > 400  # rule 3 asks every slot
    assert sum(j.counters.implausible for j in one.values()) > 0
    assert sum(j.health.jumps_in_window for j in two.values()) > 0, "implausible steps settle"
    assert sum(j.health.lost_in_window for j in one.values()) > 0
