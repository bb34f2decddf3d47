"""What Cycle.prepare, Cycle.run and Cycle.settle decide, against a plain reading of the rule.

docs/node.md, "Which cycle a TPDO answers": a slot's sample counts for the master's SYNC ``k``
only when (1) the window of ``k`` (from its SYNC to the next SYNC of any producer) holds
exactly one image and one position of the slot, (2) the earlier of the two ended at most
``latch_bound`` after the SYNC, and (3) the two windows before ``k`` are the master's own and
in each of them every slot of the station got exactly one image and one position, the first
within ``latch_bound`` of that window's SYNC. A joint's health then counts the SYNC before as
answered (share lost 0) when its sample is vouched for, else the share of its two TPDOs that
never came (all of it for one set aside with both in).

The reference below keeps every event as it came and reads the rule off sets of wire times,
without the log's fast paths, caches or bookkeeping. Two stations answer every SYNC on the
bus, the master's and another producer's, now promptly, now late (inside the window or over
the next SYNC), in part, twice, with the position first, or not at all while stalled and then
with the backlog; the master re-times its SYNC once the wire gives the exact time. The events
reach the log in wire-time order, as one station's frames do on one bus. The cycles run in
the node's order (``ros/cycle_publish.py``): SYNC ``k``, settle of cycle ``k - 1``, prepare of
``k``, the TPDOs, run of ``k``. Every joint's reason, sample, image and settled health input
must be the reference's, and every condition of rule 3 must have set samples aside.
"""

from __future__ import annotations

import random
from dataclasses import dataclass, field

from ssi_bridge.core.cycle import Cycle, CycleResult
from ssi_bridge.core.cycle_log import (
    LATE, NO_ANSWER, PARTIAL, SURPLUS, UNSETTLED, StationLog,
)
from ssi_bridge.core.joint import Joint
from ssi_bridge.protocol.settings import JointSettings

PERIOD = 0.002
BOUND = 0.0006
#: node id -> the slots the master reads
STATIONS = {3: (1, 2, 4), 5: (1, 2)}


@dataclass
class _Wire:
    """Everything the log was fed, as plain records."""

    own: dict[int, float] = field(default_factory=dict)  # seq -> wire time (the latest)
    foreign: list[float] = field(default_factory=list)
    #: (station, slot) -> [(wire time, "image" | "position", value)]
    frames: dict[tuple[int, int], list[tuple[float, str, int]]] = field(default_factory=dict)

    def syncs(self) -> list[tuple[float, bool]]:
        """Every SYNC on the bus, ascending: (wire time, the master's own)."""
        return sorted([(t, True) for t in self.own.values()] + [(t, False) for t in self.foreign])

    def window(self, station: int, slot: int, lo: float, hi: float
               ) -> tuple[list[tuple[float, int]], list[tuple[float, int]]]:
        """(images, positions) of the slot with lo <= wire time < hi, as (time, value)."""
        images = [(t, v) for t, kind, v in self.frames.get((station, slot), [])
                  if lo <= t < hi and kind == "image"]
        positions = [(t, v) for t, kind, v in self.frames.get((station, slot), [])
                     if lo <= t < hi and kind == "position"]
        return images, positions


def _reference(wire: _Wire, station: int, slot: int, seq: int) -> tuple[str, str, dict]:
    """The rule for one slot at SYNC ``seq``: (reason or "", rule-3 cause, what came)."""
    t_k = wire.own[seq]
    syncs = wire.syncs()
    at = [t for t, _own in syncs].index(t_k)
    t_next = syncs[at + 1][0] if at + 1 < len(syncs) else float("inf")
    images, positions = wire.window(station, slot, t_k, t_next)
    came = {"image": max(images)[1] if images else None,
            "position": max(positions)[1] if positions else None,
            "missing": ((not images) + (not positions)) / 2}
    if not images and not positions:
        return NO_ANSWER, "", came
    if not images or not positions:
        return PARTIAL, "", came
    if len(images) > 1 or len(positions) > 1:
        return SURPLUS, "", came
    first = min(images[0][0], positions[0][0])
    came["delay"] = first - t_k
    if first - t_k > BOUND:
        return LATE, "", came
    before = syncs[at - 2: at] if at >= 2 else []
    if len(before) < 2:
        return UNSETTLED, "start", came
    if not all(own for _t, own in before):
        return UNSETTLED, "foreign", came
    edges = [before[0][0], before[1][0], t_k]
    for s in STATIONS[station]:
        for lo, hi in zip(edges, edges[1:]):
            imgs, poss = wire.window(station, s, lo, hi)
            if len(imgs) != 1 or len(poss) != 1:
                return UNSETTLED, "count", came
            if min(imgs[0][0], poss[0][0]) - lo > BOUND:
                return UNSETTLED, "late", came
    return "", "", came


class _Joint(Joint):
    """A joint that keeps what Cycle.settle handed it."""

    def __init__(self, settings: JointSettings) -> None:
        super().__init__(settings, velocity_window=3, max_speed=1e9, stale_cycles=3)
        self.settled_with: list[tuple[int, tuple[float, float] | None]] = []

    def settle(self, seq: int, settled: tuple[float, float] | None) -> None:
        self.settled_with.append((seq, settled))
        super().settle(seq, settled)


def _answers(rng: random.Random, station: int, t: float, owed: int
             ) -> tuple[list[tuple[float, int, str]], int]:
    """One station's frames for the SYNC at ``t``: ([(wire time, slot, kind)], answers owed
    after it). A stalled station answers nothing and owes the answer; it then sends all."""
    r = rng.random()
    if r < 0.04:
        return [], owed + 1  # stalled: the answer comes with the next one
    answers = owed + 1
    start = t + 0.00005 + rng.random() * 0.0001
    if r < 0.08:
        start += BOUND + 0.0002  # late, still within the window
    elif r < 0.10:
        start += PERIOD  # late, over the next SYNC
    out: list[tuple[float, int, str]] = []
    at = start
    for _ in range(answers):
        for slot in STATIONS[station]:
            kinds = ["image", "position"]
            if rng.random() < 0.05:
                kinds.reverse()
            if rng.random() < 0.04:
                kinds.pop(rng.randrange(2))  # one frame lost
            if rng.random() < 0.03:
                kinds.append(kinds[0])  # one sent twice
            if rng.random() < 0.01:
                kinds = [kinds[0]] * 2  # one sent twice, the other lost
            for kind in kinds:
                out.append((at, slot, kind))
                at += 0.00003 + rng.random() * 0.00001
    if rng.random() < 0.03:  # one slot of the answer late
        slot = rng.choice(STATIONS[station])
        out = [(f + (BOUND if s == slot else 0.0), s, k) for f, s, k in out]
    return out, 0


def _feed_events(rng: random.Random, cycles: int) -> list[tuple[float, str, tuple]]:
    """Every event on the bus for ``cycles`` of the master, in wire-time order."""
    events: list[tuple[float, str, tuple]] = []
    owed = dict.fromkeys(STATIONS, 0)
    for k in range(1, cycles + 1):
        t = k * PERIOD + rng.random() * 0.00005
        sync_times = [t]
        events.append((t, "sync", (k,)))
        if rng.random() < 0.06:
            tf = t + 0.0007 + rng.random() * 0.001
            events.append((tf, "foreign", ()))
            sync_times.append(tf)
        for at in sync_times:
            for station in STATIONS:
                frames, owed[station] = _answers(rng, station, at, owed[station])
                for ft, slot, kind in frames:
                    events.append((ft, kind, (station, slot, k)))
    events.sort(key=lambda e: e[0])
    return events


def _check_run(result: CycleResult, wire: _Wire, seq: int, seen: dict[str, int]) -> None:
    for part in result.joints:
        station, slot = part.joint.settings.station, part.joint.slot
        want, cause, came = _reference(wire, station, slot, seq)
        where = (seq, station, slot)
        assert part.reason == want, (where, part.reason, want, cause)
        seen[cause or want or "vouched"] = seen.get(cause or want or "vouched", 0) + 1
        want_image = came["image"]
        assert part.image == (bytes([want_image & 0xFF, slot, station, 0, 0, 0, 0, 0])
                              if want_image is not None else b""), where
        if want:
            assert part.sample is None and part.output is None, where
            continue
        sample = part.sample
        assert sample is not None and part.output is not None, where
        assert sample.position == came["position"] and sample.sync_time == wire.own[seq], where
        assert sample.delay == came["delay"], where


def _check_settle(joints: list[_Joint], wire: _Wire, seq: int) -> None:
    for joint in joints:
        got_seq, settled = joint.settled_with.pop()
        assert got_seq == seq and not joint.settled_with
        if seq - 1 not in wire.own:
            assert settled is None, seq
            continue
        want, _cause, came = _reference(wire, joint.settings.station, joint.slot, seq - 1)
        lost = 0.0 if not want else came["missing"] or 1.0
        assert settled == (wire.own[seq - 1], lost), (seq, joint.name, want)


def test_prepare_run_settle_follow_the_rule() -> None:
    rng = random.Random(33)
    logs = {node: StationLog(BOUND, slots=slots) for node, slots in STATIONS.items()}
    joints = [_Joint(JointSettings(name=f"s{node}j{slot}", slot=slot, station=node))
              for node, slots in STATIONS.items() for slot in slots]
    rng.shuffle(joints)  # the configured order is not the stations'
    cycle = Cycle({j.name: j for j in joints}, logs)
    wire = _Wire()
    seen: dict[str, int] = {}
    pending: CycleResult | None = None
    last = 0
    incomplete = 0

    def run(seq: int) -> None:
        nonlocal pending, incomplete
        result = cycle.run(seq, wire.own[seq], settle=False)
        _check_run(result, wire, seq, seen)
        incomplete += any(p.output is None for p in result.joints)
        assert cycle.incomplete_cycles == incomplete
        pending = result

    for t, kind, args in _feed_events(rng, 800):
        if kind == "sync":
            (seq,) = args
            if last:
                run(last)
            estimate = t - 0.00002
            wire.own[seq] = estimate
            for log in logs.values():
                log.sync(seq, estimate)
            if pending is not None:  # the cycle before, finished after this SYNC
                cycle.settle(pending)
                _check_settle(joints, wire, pending.seq)
            cycle.prepare(seq)
            if rng.random() < 0.9:  # the exact time, once the wire gave it
                wire.own[seq] = t
                for log in logs.values():
                    log.sync(seq, t)
            last = seq
        elif kind == "foreign":
            wire.foreign.append(t)
            for log in logs.values():
                log.foreign_sync(t)
        else:
            station, slot, k = args
            value = k * 100 + slot
            wire.frames.setdefault((station, slot), []).append((t, kind, value))
            if kind == "image":
                image = bytes([value & 0xFF, slot, station, 0, 0, 0, 0, 0])
                logs[station].image(slot, t, image, k)
            else:
                logs[station].position(slot, t, value)
    # every way to be set aside, and every condition of rule 3, must have been met often
    assert 5 <= seen.get("start", 0) <= 2 * len(joints), seen  # the first two cycles
    for reason in ("vouched", NO_ANSWER, PARTIAL, SURPLUS, LATE, "foreign", "count", "late"):
        assert seen.get(reason, 0) >= 20, seen
