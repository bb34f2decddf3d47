"""What every benchmark in bench/ shares: the output convention and a process's CPU time.

Each figure is one JSON object per line, printed and appended to bench/results/latest.jsonl:
``metric``, ``value``, ``unit`` and, where a baseline was measured in the same run,
``baseline`` and ``ratio`` (value / baseline); ``note`` says what was compared. A benchmark
reports, it never fails the run: an exception becomes a record with ``error``.
"""

from __future__ import annotations

import json
import os
import traceback
from collections.abc import Callable, Iterable
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results" / "latest.jsonl"


def figure(metric: str, value: float, unit: str, baseline: float | None = None,
           note: str = "", digits: int = 3) -> dict:
    """One record; ``ratio`` only where a non-zero baseline was measured."""
    rec: dict = {"metric": metric, "value": round(value, digits), "unit": unit}
    if baseline:
        rec["baseline"] = round(baseline, digits)
        rec["ratio"] = round(value / baseline, 3)
    if note:
        rec["note"] = note
    return rec


def emit(records: list[dict], metric: str, value: float, unit: str,
         baseline: float | None = None, note: str = "", digits: int = 3) -> dict:
    """Print one figure now and keep it for :func:`save`."""
    return emit_record(records, figure(metric, value, unit, baseline, note, digits))


def emit_record(records: list[dict], rec: dict) -> dict:
    """Print a ready record now and keep it for :func:`save`."""
    records.append(rec)
    print(json.dumps(rec), flush=True)
    return rec


def run_parts(records: list[dict], parts: Iterable[Callable[[list[dict]], object]]) -> None:
    """Run each part; one that raises becomes an ``error`` record and the next one runs."""
    for part in parts:
        try:
            part(records)
        except Exception as err:  # noqa: BLE001 - a benchmark reports, it never fails
            emit_record(records, {"metric": part.__name__,
                                  "error": f"{type(err).__name__}: {err}",
                                  "note": traceback.format_exc(limit=3)[-800:]})


def save(records: list[dict], path: Path = RESULTS) -> None:
    """Append ``records`` to results/latest.jsonl (an unwritable file is reported, not raised)."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("a", encoding="utf-8") as fh:
            for rec in records:
                fh.write(json.dumps(rec) + "\n")
    except OSError as err:
        print(json.dumps({"metric": "results_file", "error": str(err)}), flush=True)


def percentile(values: list[float], q: float) -> float:
    """The ``q`` quantile (0..1) of ``values`` by rank (nan for none): no numpy needed."""
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))] if ordered else float("nan")


def cpu_seconds(pid: int) -> float:
    """utime + stime of ``pid`` (all its threads) in seconds, from /proc/<pid>/stat."""
    stat = Path(f"/proc/{pid}/stat").read_text()
    fields = stat[stat.rindex(")") + 2:].split()
    # fields[0] is field 3 (state); utime and stime are fields 14 and 15
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
