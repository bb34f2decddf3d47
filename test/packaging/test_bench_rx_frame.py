"""bench/rx_frame.py measures the master's receive path as the node runs it: every TPDO it
sends reaches the slot table through the TPDO routes, none raises in its handler (a frame
that raised would be timed as the listener's error path, not the decode the bench reports).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def test_the_receive_bench_routes_every_frame_without_a_handler_error() -> None:
    out = subprocess.run([sys.executable, "bench/rx_frame.py", "48", "1"], capture_output=True,
                         text=True, cwd=REPO, timeout=120)
    assert out.returncode == 0, out.stderr[-3000:]
    assert "raised in" not in out.stderr, out.stderr[-3000:]
    assert "(48 frames counted)" in out.stdout, out.stdout
