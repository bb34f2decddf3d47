"""The cycle core's hot path alone, in-process: deciding one cycle of N joints and building its
joint_states, without a node, a bus or another thread.

``python bench/cycle_decide.py [joints] [cycles]``: one station's frame log fed like the
simulated station answers (every slot's image and position once per SYNC, 60 us apart,
positions moving; ``Cycle.prepare`` between the SYNC and its answers, as the cycle thread),
and a ``core/cycle.Cycle`` of N joints (slots 1..N, GENERIC encoders with
their frame checks) deciding each SYNC as the node does: the part before ``publish()``
(``run(settle=False)`` and the JointState), then the health of the SYNC before
(``settle``). Prints median / p99 (us) per cycle of each part after a warm-up of 500 cycles:
``prepare`` (rule 3 asked ahead, the cycle thread), ``feed`` (the frame log's records of the
cycle's frames, what the receive thread adds per frame), ``decide`` (``Cycle.run``), ``build`` (the JointState) and ``settle``.
The thread's CPU time (``time.thread_time_ns``), in-process without the node's other threads:
the figures to compare changes of the per-joint path by on a shared machine, not the node's
latency (``bench_node.py``).
"""

from __future__ import annotations

import gc
import statistics
import sys
import time

from ssi_bridge.core.cycle import Cycle
from ssi_bridge.core.cycle_log import StationLog
from ssi_bridge.core.joint import Joint
from ssi_bridge.protocol.images import encode_input
from ssi_bridge.protocol.registers import Reg
from ssi_bridge.protocol.settings import JointSettings
from ssi_bridge.ros.messages import JointStates

PERIOD = 1 / 480
WARM_UP = 500


def _p99(values: list[float]) -> float:
    return sorted(values)[int(0.99 * (len(values) - 1))]


def main(argv: list[str]) -> int:
    """Run the cycles and print the figures."""
    n = int(argv[0]) if argv else 8
    cycles = int(argv[1]) if len(argv) > 1 else 5000
    log = StationLog(0.0008, slots=tuple(range(1, n + 1)))
    joints = {f"j{s}": Joint(JointSettings(name=f"j{s}", slot=s), velocity_window=5,
                             max_speed=-1.0, stale_cycles=10) for s in range(1, n + 1)}
    core = Cycle(joints, {0: log})
    states = JointStates()  # the node's: one message filled each cycle
    parts: dict[str, list[float]] = {"prepare": [], "feed": [], "decide": [], "build": [],
                                     "settle": []}
    clock = time.thread_time_ns  # CPU time: what another process on the core takes is not counted
    gc.collect()
    for k in range(1, cycles + WARM_UP + 1):
        t = k * PERIOD
        log.sync(k, t)
        p0 = clock()
        core.prepare(k)  # the cycle thread, while the answers are on the wire
        p1 = clock()
        answers = [(slot, 37 * k * slot) for slot in range(1, n + 1)]
        images = [encode_input(pos & 0xFFFFFF, int(Reg.REG_SSI_FRAME), False, False, False,
                               0, 0, 0) for _slot, pos in answers]
        t0 = clock()
        for (slot, pos), image in zip(answers, images):
            log.image(slot, t + 0.0001 + 0.00006 * slot, image, k)
            log.position(slot, t + 0.0001 + 0.00006 * slot + 0.00003, pos)
        t1 = clock()
        result = core.run(k, t, settle=False)
        t2 = clock()
        states.fill(result, int(t * 1e9), "base")
        t3 = clock()
        core.settle(result)
        t4 = clock()
        if k > WARM_UP:
            for name, dt in zip(parts, (p1 - p0, t1 - t0, t2 - t1, t3 - t2, t4 - t3)):
                parts[name].append(dt / 1e3)
    print(f"{n} joint(s), {cycles} cycles, us median / p99: " + ", ".join(
        f"{name} {statistics.median(v):.1f} / {_p99(v):.1f}" for name, v in parts.items())
        + f", left out {core.incomplete_cycles}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
