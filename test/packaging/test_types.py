"""The type check of make test: mypy, as setup.cfg ``[mypy]`` configures it (the folders it
checks and how strictly: docs/architecture.md "Type checking").

Run here, in a subprocess beside the other tests (pytest-xdist), rather than before pytest in
the Makefile: it adds no wall time to ``make test`` and its report is the failure's message.
"""

from __future__ import annotations

import configparser
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def test_the_type_check_passes() -> None:
    out = subprocess.run([sys.executable, "-m", "mypy", "--config-file", "setup.cfg"],
                         capture_output=True, text=True, cwd=REPO, timeout=300)
    assert out.returncode == 0, out.stdout[-8000:] + out.stderr[-2000:]
    assert out.stdout.startswith("Success: no issues found"), out.stdout[-3000:]


def test_the_strict_folders_are_the_documented_ones() -> None:
    """setup.cfg and docs/architecture.md name the same folders as checked --strict."""
    config = configparser.ConfigParser()
    config.read(REPO / "setup.cfg")
    assert config.getboolean("mypy", "strict")
    files = [f.strip() for f in config.get("mypy", "files").split(",")]
    assert files, "setup.cfg [mypy] files names what is checked"
    docs = (REPO / "docs" / "architecture.md").read_text(encoding="utf-8")
    section = docs.split("## Type checking", 1)[1].split("\n## ", 1)[0]
    for path in files:
        assert f"`{path}" in section, f"{path}: checked --strict, not in the docs' table"


def test_each_exception_to_strict_is_documented() -> None:
    """Every per-module section of setup.cfg that loosens the check on a package module
    (``[mypy-ssi_bridge.…]``) is named in the docs' table, so no folder is quietly exempt."""
    config = configparser.ConfigParser()
    config.read(REPO / "setup.cfg")
    sections = [name.removeprefix("mypy-") for name in config.sections()
                if name.startswith("mypy-ssi_bridge")]
    docs = (REPO / "docs" / "architecture.md").read_text(encoding="utf-8")
    table = docs.split("## Type checking", 1)[1].split("\n## ", 1)[0]
    for section in sections:
        assert f"[mypy-{section}]" in table, f"setup.cfg [mypy-{section}] not in the docs' table"
