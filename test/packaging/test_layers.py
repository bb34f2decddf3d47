"""The three layers and what may import what (docs/architecture.md), checked by import-linter.

``.importlinter`` holds the contracts: the driver never imports the simulator (but for the
node's supervisor of its simulated station), the simulator never imports the driver or ROS,
``protocol/`` is pure, only ``ros/``, ``record/`` and ``tools/`` import ROS, the order inside
the driver (tools over ros over core | client | record), only ``record/`` imports mcap, no
import circles.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def _lint_imports() -> list[str]:
    exe = Path(sys.executable).with_name("lint-imports")
    return [str(exe)] if exe.exists() else [shutil.which("lint-imports") or "lint-imports"]


def test_the_import_contracts_hold():
    out = subprocess.run([*_lint_imports(), "--config", str(REPO / ".importlinter"),
                          "--no-cache"], capture_output=True, text=True, cwd=REPO,
                         timeout=300)
    assert out.returncode == 0, out.stdout[-6000:] + out.stderr[-2000:]
    assert "0 broken" in out.stdout, out.stdout[-3000:]


def test_the_contracts_cover_every_top_level_package():
    """A new sub-package of ssi_bridge must be placed in a layer (named in a contract)."""
    text = (REPO / ".importlinter").read_text()
    packages = sorted(p.name for p in (REPO / "ssi_bridge").iterdir()
                      if (p / "__init__.py").exists())
    missing = [p for p in packages if f"ssi_bridge.{p}\n" not in text]
    assert not missing, f"packages in no import contract: {missing}"



def test_no_module_of_the_package_or_the_benchmarks_is_over_400_lines():
    long = {str(p.relative_to(REPO)): n for folder in ("ssi_bridge", "bench")
            for p in (REPO / folder).rglob("*.py")
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > 400}
    assert not long, f"modules over 400 lines: {long}"
