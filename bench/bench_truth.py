"""Benchmark: the node under disturbance, every published sample held to the truth.

Runs the cases of ``test/ros/test_node_truth.py`` (stalls of the simulated station, a
queueing station's backlog, a second SYNC producer, a stray SYNC, CAN frame loss) and of
``test_node_truth_matrix.py`` (the slow tier's matrix on two stations and on eight joints, a
station killed and started again) as real node processes beside two CPU-burning processes (one per core,
stopped by PID at the end), and prints per case, from the truth oracle
(``test/support/truth.py``):

* ``truth_<case>_checked``: published samples held against the truth
* ``truth_<case>_worst_residual_counts``: the largest |published - true position| at the
  stamp, REG_SSI_POS counts (the rule: <= 1 + max speed x ``latch_bound_s``)
* ``truth_<case>_worst_velocity_error``: the largest |published - true velocity| (rad/s)
* ``truth_<case>_violations``: samples beyond their bound (the rule: 0)
* ``truth_<case>_set_aside``: samples that arrived but could not be vouched for
* ``truth_<case>_left_out_cycles``: ~/status channels left out of joint_states
* ``truth_<case>_diagnostics_after_s``: from the disturbance's start to the first non-OK
  status of the joint or the bus received

No baseline: these are counts against a rule, not speeds. Prints one JSON object per line and
appends them to bench/results/latest.jsonl; never fails (an error becomes a line with
"error"; exit status 0).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from benchlib import emit, emit_record, save  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
TESTS = ("test/ros/test_node_truth.py", "test/ros/test_node_truth_matrix.py")


def _burners(n: int) -> list[subprocess.Popen]:
    return [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]


def _stop(procs: list[subprocess.Popen]) -> None:
    for p in procs:
        if p.poll() is None:
            os.kill(p.pid, signal.SIGKILL)
            p.wait(5)


def main() -> None:
    records: list[dict] = []
    with tempfile.TemporaryDirectory() as tmp:
        report = Path(tmp) / "truth.jsonl"
        env = dict(os.environ, SSI_BRIDGE_TRUTH_REPORT=str(report))
        load = _burners(2)
        try:
            run = subprocess.run(
                [sys.executable, "-m", "pytest", *TESTS, "-q", "-n", "0", "-m", "",
                 "-p", "no:cacheprovider"], cwd=REPO, env=env, capture_output=True,
                text=True, timeout=1800)
        except Exception as err:  # noqa: BLE001 - a benchmark reports, never fails
            emit_record(records, {"metric": "truth", "error": repr(err)})
            save(records)
            return
        finally:
            _stop(load)
        tail = run.stdout.strip().splitlines()[-1:] if run.stdout.strip() else [""]
        note = "beside two CPU burners; pytest: " + tail[0]
        rows = ([json.loads(line) for line in report.read_text().splitlines()]
                if report.exists() else [])
        if not rows:
            emit_record(records, {"metric": "truth", "error": run.stdout[-2000:]})
        for row in rows:
            case = row["case"]
            emit(records, f"truth_{case}_checked", row["checked"], "samples", note=note)
            emit(records, f"truth_{case}_worst_residual_counts",
                 row["worst_residual_counts"], "counts",
                 note=f"rule: <= 1 + max speed x latch_bound_s ({row['latch_bound_s']} s)")
            emit(records, f"truth_{case}_worst_velocity_error", row["worst_velocity_error"],
                 "rad/s")
            emit(records, f"truth_{case}_violations", row["violations"], "samples",
                 note="rule: 0")
            emit(records, f"truth_{case}_set_aside", row["set_aside"], "samples")
            emit(records, f"truth_{case}_left_out_cycles", row["left_out_cycles"], "cycles")
            if row["diagnostics_after_s"] is not None:
                emit(records, f"truth_{case}_diagnostics_after_s", row["diagnostics_after_s"],
                     "s", note="first non-OK joint or bus status received")
    save(records)


if __name__ == "__main__":
    main()
