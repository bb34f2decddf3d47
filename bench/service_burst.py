"""Benchmark part of bench_node.py: a burst of service calls to the node at 1 kHz.

The installed node runs one simulated encoder at 1000 Hz; ``bench/node_subscriber.py`` records
every joint_states message in another process (SCHED_FIFO 3 where permitted, as in
node_procs.py: a starved subscriber would count its own backlog). After a warm-up, 4 clients (4 rclpy nodes in
this process, KEEP_ALL queues so the clients themselves drop nothing) each send 250
``~/read_register`` calls at once, 1000 in all, and wait for every answer (success, or the
node's prompt "busy: N queued" refusal). Reported, same run:

* ``service_burst_answered_fraction``: answers / calls (goal 1.0: none lost)
* ``service_burst_busy_fraction``: refusals "busy: N queued" / calls (information)
* ``service_burst_answer_p50_ms`` / ``_p99_ms``: call -> answer time over all 1000
* ``service_burst_joint_states_rate_hz``: joint_states per s from the first call to the last
  answer, baseline = the rate over 2 s before the clients' process starts (goal ratio >= 0.9)

``python bench/service_burst.py`` runs it alone; ``make bench ONLY=node`` runs it after the
rate/latency cases. Prints JSON lines and appends them to bench/results/latest.jsonl.
"""

from __future__ import annotations

import os
import sys
import tempfile
import threading
import time
import traceback
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from benchlib import cpu_seconds, save  # noqa: E402
from benchlib import emit_record as emit  # noqa: E402
from node_cases import NODE_NS, RATE_HZ, node_cmd  # noqa: E402
from node_measure import WARMUP_S, publisher_and_subscriber  # noqa: E402
from node_procs import dds_env, domain_id, subscriber_scheduling  # noqa: E402

CLIENTS = 4
CALLS_PER_CLIENT = 250
BEFORE_S = 2.0
ANSWER_TIMEOUT_S = 120.0


def _rate(samples: Path, t0_ns: int, t1_ns: int) -> float:
    """joint_states messages received per second in [t0, t1) (wall ns)."""
    n = 0
    with open(samples) as f:
        for line in f:
            recv = int(line.split()[0])
            n += t0_ns <= recv < t1_ns
    return n / ((t1_ns - t0_ns) / 1e9)


def burst(domain_id: int, service: str) -> dict:
    """Send CLIENTS x CALLS_PER_CLIENT calls at once; (send, answer, message) of each."""
    import rclpy
    from rclpy.executors import MultiThreadedExecutor
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from ssi_bridge_msgs.srv import ReadRegister

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id)
    qos = QoSProfile(depth=1, history=HistoryPolicy.KEEP_ALL,
                     reliability=ReliabilityPolicy.RELIABLE)
    nodes = [rclpy.create_node(f"burst_client_{os.getpid()}_{i}", context=context)
             for i in range(CLIENTS)]
    executor = MultiThreadedExecutor(num_threads=2, context=context)
    for node in nodes:
        executor.add_node(node)
    spin = threading.Thread(target=executor.spin, daemon=True)
    spin.start()
    try:
        clients = [node.create_client(ReadRegister, service, qos_profile=qos) for node in nodes]
        for client in clients:
            if not client.wait_for_service(timeout_sec=20.0):
                raise RuntimeError(f"{service} not available")
        sent: list[float] = []
        answered: list[float | None] = [None] * (CLIENTS * CALLS_PER_CLIENT)
        messages: list[str] = [""] * len(answered)
        done = threading.Event()
        left = [len(answered)]
        lock = threading.Lock()

        def on_done(index: int, future) -> None:  # noqa: ANN001
            answered[index] = time.monotonic()
            res = future.result()
            messages[index] = "ok" if res.success else res.message
            with lock:
                left[0] -= 1
                if left[0] == 0:
                    done.set()

        t_wall0 = time.time_ns()
        futures = []
        for k in range(CALLS_PER_CLIENT):
            for c, client in enumerate(clients):
                index = len(sent)
                sent.append(time.monotonic())
                future = client.call_async(ReadRegister.Request(address=1))  # REG_MAGIC_NO
                future.add_done_callback(lambda f, i=index: on_done(i, f))
                futures.append(future)
        done.wait(ANSWER_TIMEOUT_S)
        t_wall1 = time.time_ns()
        return {"sent": sent, "answered": answered, "messages": messages,
                "t0_ns": t_wall0, "t1_ns": t_wall1}
    finally:
        executor.shutdown(timeout_sec=1.0)
        for node in nodes:
            node.destroy_node()
        context.try_shutdown()


def run(records: list[dict], extra: dict | None = None) -> None:
    import numpy as np

    domain = domain_id()
    env = dds_env(domain)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    with tempfile.TemporaryDirectory(prefix="bench_burst_") as tmp:
        work = Path(tmp)
        # the node scheduled as this process, as the burst has always run it
        with publisher_and_subscriber("burst", node_cmd(1, domain, work, extra),
                                      f"{NODE_NS}/joint_states", env, work,
                                      pub_preexec=None) as running:
            node = running.pub
            time.sleep(WARMUP_S)
            # the baseline window ends before the clients' process starts: its set-up (rclpy
            # init, four nodes, discovery) takes a core for a second or two and is no part of
            # the burst
            cpu0, m0, w0 = cpu_seconds(node.pid), time.monotonic(), time.time_ns()
            time.sleep(BEFORE_S)
            cpu1, m1, w1 = cpu_seconds(node.pid), time.monotonic(), time.time_ns()
            result = burst(domain, f"{NODE_NS}/ssi_bridge/read_register")
            cpu2, m2 = cpu_seconds(node.pid), time.monotonic()
            time.sleep(0.2)
        before = _rate(running.samples, w0, w1)
        during = _rate(running.samples, result["t0_ns"], result["t1_ns"])
    n = len(result["sent"])
    times = [(a - s) * 1e3 for s, a in zip(result["sent"], result["answered"]) if a is not None]
    busy = sum(m.startswith("read_register: busy:") for m in result["messages"])
    other = [m for m in result["messages"] if m not in ("ok", "") and "busy:" not in m]
    note = (f"{CLIENTS} clients x {CALLS_PER_CLIENT} ~/read_register calls at once to the node at "
            f"{RATE_HZ:g} Hz (1 encoder), {subscriber_scheduling()}"
            + "".join(f", {k} {v}" for k, v in (extra or {}).items()))
    emit(records, {"metric": "service_burst_answered_fraction", "value": len(times) / n,
                   "unit": "", "baseline": 1.0, "ratio": round(len(times) / n, 4),
                   "goal": "ratio >= 1.0", "goal_met": len(times) == n,
                   "note": f"answers / calls; {note}"
                           + (f"; unexpected answers: {other[:3]}" if other else "")})
    emit(records, {"metric": "service_burst_busy_fraction", "value": round(busy / n, 4),
                   "unit": "", "note": f"prompt 'busy: N queued' refusals / calls; {note}"})
    if times:
        for q in (50, 99):
            emit(records, {"metric": f"service_burst_answer_p{q}_ms",
                           "value": round(float(np.percentile(times, q)), 2), "unit": "ms",
                           "note": f"call -> answer time, all answers; {note}"})
    cpu_before, cpu_during = (cpu1 - cpu0) / (m1 - m0), (cpu2 - cpu1) / (m2 - m1)
    emit(records, {"metric": "service_burst_node_cpu_s_per_s", "value": round(cpu_during, 3),
                   "unit": "s/s", "baseline": round(cpu_before, 3),
                   "ratio": round(cpu_during / cpu_before, 3) if cpu_before else None,
                   "note": f"node process CPU s per s during the burst (baseline: before); "
                           f"{note}"})
    ratio = during / before if before else 0.0
    emit(records, {"metric": "service_burst_joint_states_rate_hz", "value": round(during, 1),
                   "unit": "Hz", "baseline": round(before, 1), "ratio": round(ratio, 3),
                   "goal": "ratio >= 0.9", "goal_met": ratio >= 0.9,
                   "note": f"joint_states received per s from the first call to the last "
                           f"answer; baseline = the {BEFORE_S:g} s before the clients start; {note}"})


def main(argv: list[str] | None = None) -> int:
    """``--cycle-priority N`` runs the node with that cycle_priority (A/B of the scheduling)."""
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycle-priority", type=int, default=None,
                        help="the node's cycle_priority (default: the node's default)")
    args = parser.parse_args(argv)
    extra = None if args.cycle_priority is None else {"cycle_priority": args.cycle_priority}
    records: list[dict] = []
    try:
        run(records, extra)
    except Exception as err:  # noqa: BLE001 - a benchmark reports, never fails
        emit(records, {"metric": "service_burst", "error": f"{type(err).__name__}: {err}",
                       "note": traceback.format_exc(limit=3)[-800:]})
    save(records)
    return 0


if __name__ == "__main__":
    sys.exit(main())
