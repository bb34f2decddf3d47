"""Compare two ``bench/heap_split.py`` runs made side by side (their JSON lines saved to files).

``python bench/soak_compare.py old.jsonl new.jsonl [--warmup 60]`` prints, per run and for
RSS and each memory figure of the samples: the least-squares slope after the warm-up in MB
per hour, its standard error (from the residuals; the samples are autocorrelated, so it
understates the noise), the slopes of the first and second half of the window (their spread
is the better noise figure), and the residuals' standard deviation in MB. The last line is
the difference of the RSS slopes (first run minus second) with the larger of the two runs'
half-window spreads, which is what the acceptance rule of a writer change is read against.
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np

FIGURES = ("rss_mb", "malloc_in_use_mb", "malloc_free_mb", "malloc_heap_mb", "rss_heap_mb",
           "rss_arenas_mb", "rss_pymalloc_mb", "rss_anon_other_mb")


def load(path: str) -> list[dict]:
    """The sample lines of one run (the result line left out)."""
    with open(path) as f:
        return [row for row in map(json.loads, f) if "t" in row and "result" not in row]


def fit(t: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """Slope (MB/h), its standard error (MB/h) and the residuals' std (MB)."""
    (a, b), cov = np.polyfit(t, y, 1, cov=True)
    resid = y - (a * t + b)
    return a * 3600.0, float(np.sqrt(cov[0, 0])) * 3600.0, float(resid.std())


def describe(rows: list[dict], warmup: float) -> dict[str, dict[str, float]]:
    """Per figure: slope, se, first and second half slopes, residual std."""
    rows = [r for r in rows if r["t"] >= warmup]
    t = np.array([r["t"] for r in rows], dtype=float)
    half = len(t) // 2
    out = {}
    for key in FIGURES:
        if key not in rows[0]:
            continue
        y = np.array([r[key] for r in rows], dtype=float)
        slope, se, sd = fit(t, y)
        out[key] = {"slope": slope, "se": se, "first": fit(t[:half], y[:half])[0],
                    "second": fit(t[half:], y[half:])[0], "resid_sd": sd,
                    "start": float(y[0]), "end": float(y[-1])}
    out["_window"] = {"from_s": float(t[0]), "to_s": float(t[-1]), "samples": float(len(t)),
                      "msgs_per_s": float(rows[-1].get("msgs_per_s", 0.0)),
                      "files": float(rows[-1].get("files", 0))}
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("first")
    parser.add_argument("second")
    parser.add_argument("--warmup", type=float, default=60.0)
    args = parser.parse_args(argv)
    runs = {}
    for path in (args.first, args.second):
        stats = runs[path] = describe(load(path), args.warmup)
        w = stats["_window"]
        print(f"# {path}: {w['from_s']:.0f}-{w['to_s']:.0f} s, {w['samples']:.0f} samples, "
              f"{w['msgs_per_s']:.0f} msg/s, {w['files']:.0f} files")
        for key, s in stats.items():
            if key.startswith("_"):
                continue
            print(f"  {key:18s} {s['start']:8.3f} -> {s['end']:8.3f} MB  slope {s['slope']:+7.3f}"
                  f" +- {s['se']:.3f} MB/h  halves {s['first']:+7.3f} {s['second']:+7.3f}"
                  f"  resid sd {s['resid_sd']:.3f} MB")
    a, b = (runs[p]["rss_mb"] for p in (args.first, args.second))
    spread = max(abs(a["first"] - a["second"]), abs(b["first"] - b["second"]))
    print(f"rss slope difference (first - second): {a['slope'] - b['slope']:+.3f} MB/h; "
          f"half-window spread up to {spread:.3f} MB/h")
    return 0


if __name__ == "__main__":
    sys.exit(main())
