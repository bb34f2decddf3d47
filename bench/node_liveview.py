"""The live view's cost (``foxglove.port``): the node's CPU with Foxglove WebSocket clients.

One node with 1 encoder at 1 kHz and its Foxglove WebSocket server on; its CPU s/s in
alternating windows with no client, one client (``bench/liveview_client.py``, another
process) subscribed to joint_states, and one subscribed to every node topic; medians of
:data:`LIVEVIEW_ROUNDS` rounds (``node_1enc_liveview_*``).
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import time
from pathlib import Path

from benchlib import cpu_seconds
from benchlib import emit_record as emit
from node_cases import NODE_NS, RATE_HZ, node_cmd
from node_measure import WARMUP_S, publisher_and_subscriber, wait_for
from node_procs import stop

LIVEVIEW_CLIENT = Path(__file__).resolve().parent / "liveview_client.py"
LIVEVIEW_ROUNDS = 3
LIVEVIEW_WINDOW_S = 3.0
#: what the client subscribes to: joint_states alone (a plot panel), or every node topic
LIVEVIEW_CASES = {"client": [f"{NODE_NS}/joint_states"],
                  "all_topics": [f"{NODE_NS}/joint_states", f"{NODE_NS}/ssi_bridge/status",
                                 "/diagnostics", f"{NODE_NS}/ssi_bridge/events"]}


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _cpu_window(pid: int) -> tuple[float, float, int, int]:
    """(CPU s, elapsed s, wall ns start, wall ns end) of ``pid`` over LIVEVIEW_WINDOW_S."""
    cpu0, m0, w0 = cpu_seconds(pid), time.monotonic(), time.time_ns()
    time.sleep(LIVEVIEW_WINDOW_S)
    return cpu_seconds(pid) - cpu0, time.monotonic() - m0, w0, time.time_ns()


def measure_liveview(domain_id: int, env: dict[str, str], work: Path) -> dict[str, list[float]]:
    """One node (1 encoder, 1 kHz, live view on), alternating windows with no client, one
    client on joint_states and one on every topic: node CPU s/s, and the joint_states rates
    the WebSocket client and the DDS subscriber received. Every process is stopped by PID.

    :raises RuntimeError: the node, the subscriber or a client did not start
    """
    port = _free_port()
    cmd = node_cmd(1, domain_id, work, {"foxglove.port": port})
    windows: dict[str, list[tuple[float, float, int, int]]] = {"idle": [], **{
        case: [] for case in LIVEVIEW_CASES}}
    ws_rates: list[float] = []
    with publisher_and_subscriber("lv", cmd, f"{NODE_NS}/joint_states", env, work,
                                  sub_preexec=None, pub_preexec=None) as run:
        node = run.pub
        time.sleep(WARMUP_S)
        for r in range(LIVEVIEW_ROUNDS):
            windows["idle"].append(_cpu_window(node.pid))
            for case, topics in LIVEVIEW_CASES.items():
                tag = f"lv_{case}_{r}"
                c_ready, c_out, c_log = (work / f"{tag}.ready", work / f"{tag}.out",
                                         work / f"{tag}.log")
                with open(c_log, "wb") as log:
                    client = subprocess.Popen(
                        [sys.executable, str(LIVEVIEW_CLIENT), f"ws://127.0.0.1:{port}",
                         ",".join(topics), str(c_ready), str(c_out)], stdout=log,
                        stderr=subprocess.STDOUT, env=env, cwd=work, start_new_session=True)
                try:
                    wait_for(c_ready, [(client, c_log), (node, run.pub_log)],
                             f"live view client on {topics}")
                    time.sleep(0.5)
                    windows[case].append(_cpu_window(node.pid))
                finally:
                    stop(client)
                if case == "client":
                    n, first, last = (int(v) for v in c_out.read_text().split())
                    ws_rates.append((n - 1) / ((last - first) / 1e9))
                time.sleep(0.5)  # the server notices the disconnect; serializing stops
    import numpy as np

    recv = np.loadtxt(run.samples, dtype=np.int64, ndmin=2)[:, 0]
    out: dict[str, list[float]] = {"ws_rate_hz": ws_rates}
    for case, wins in windows.items():
        cycles = [int(((recv >= w0) & (recv < w1)).sum()) for _, _, w0, w1 in wins]
        out[case] = [cpu / el for cpu, el, _, _ in wins]
        out[f"{case}_dds_rate_hz"] = [n / (el or 1.0) for (_, el, _, _), n in zip(wins, cycles)]
    return out


def report_liveview(records: list[dict], lv: dict[str, list[float]], plain: dict) -> None:
    """Medians of the alternating windows; baselines from the same node or the same run
    (``plain``: the 1-encoder node's :func:`node_measure.measure` result, live view off)."""
    med = {k: statistics.median(v) for k, v in lv.items()}
    rows = [
        ("client_cpu_s_per_s", med["client"], med["idle"], "s/s",
         "node CPU with one Foxglove WebSocket client subscribed to joint_states; baseline = "
         "the same node process, live view server on, no client (alternating windows)"),
        ("all_topics_cpu_s_per_s", med["all_topics"], med["idle"], "s/s",
         "node CPU with one client subscribed to joint_states, ~/status, /diagnostics and "
         "~/events (~/status is then built every cycle); baseline = same node, no client"),
        ("idle_cpu_s_per_s", med["idle"], plain["cpu_s_per_s"], "s/s",
         "node CPU with the live view server on and no client; baseline = node with "
         "foxglove.port 0 (the default) measured earlier in this run"),
        ("ws_rate_hz", med["ws_rate_hz"], med["client_dds_rate_hz"], "Hz",
         "joint_states per second received by the WebSocket client; baseline = joint_states "
         "per second received over DDS by the subscriber (also a Python process) in the same "
         "windows"),
    ]
    for name, value, base, unit, note in rows:
        rec = {"metric": f"node_1enc_liveview_{name}", "value": round(value, 3), "unit": unit,
               "baseline": round(base, 3)}
        if base:
            rec["ratio"] = round(value / base, 3)
        rec["note"] = (f"{note}; 1 encoder at {RATE_HZ:g} Hz, median of {LIVEVIEW_ROUNDS} "
                       f"windows of {LIVEVIEW_WINDOW_S:g} s")
        emit(records, rec)
