"""resolve_bag_path: names under the recording root, each refusal with its own message."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from datetime import datetime
from pathlib import Path

import pytest

from ssi_bridge.exceptions import RecordingError
from ssi_bridge.record.session import resolve_bag_path

#: capabilities that let uid 0 ignore file modes
DAC_CAPS = "-dac_override,-dac_read_search"


def test_empty_name_is_timestamped(tmp_path: Path) -> None:
    now = datetime(2025, 3, 4, 5, 6, 7)
    first = resolve_bag_path(tmp_path, "", now=now)
    assert first == tmp_path.resolve() / "ssi_bridge_2025_03_04-05_06_07"
    first.mkdir()
    assert resolve_bag_path(tmp_path, "  ", now=now).name == "ssi_bridge_2025_03_04-05_06_07_1"


@pytest.mark.parametrize("name", ["run1", "day/run1", "./a/../run1"])
def test_relative_names_stay_under_root(tmp_path: Path, name: str) -> None:
    path = resolve_bag_path(tmp_path, name)
    assert path.is_relative_to(tmp_path.resolve()) and path.name == "run1"


@pytest.mark.parametrize("name", ["../escape", "/etc/bag", "a/../../x", "."])
def test_outside_root_refused(tmp_path: Path, name: str) -> None:
    with pytest.raises(RecordingError, match="outside the recording root"):
        resolve_bag_path(tmp_path / "root", name)


def test_existing_bag_refused(tmp_path: Path) -> None:
    (tmp_path / "run1").mkdir()
    with pytest.raises(RecordingError, match="already exists"):
        resolve_bag_path(tmp_path, "run1")


def test_missing_root_refused(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match="does not exist"):
        resolve_bag_path(tmp_path / "missing", "run1")


def test_unwritable_root_refused(tmp_path: Path) -> None:
    """A mode 0555 root; as uid 0 the check runs without CAP_DAC_OVERRIDE so modes apply."""
    root = tmp_path / "ro"
    root.mkdir(mode=0o555)
    root.chmod(0o555)
    code = ("import sys; from pathlib import Path\n"
            "from ssi_bridge.exceptions import RecordingError\n"
            "from ssi_bridge.record.session import resolve_bag_path\n"
            "from ssi_bridge.record.bag import BagRecorder\n"
            "for call in (lambda: resolve_bag_path(Path(sys.argv[1]), 'run1'),\n"
            "             lambda: BagRecorder.open(Path(sys.argv[1]) / 'run1')):\n"
            "    try:\n        call()\n    except RecordingError as err:\n        print(err)\n"
            "    else:\n        print('ACCEPTED')\n")
    prefix: list[str] = []
    if os.geteuid() == 0:
        setpriv = shutil.which("setpriv")
        if setpriv is None:
            pytest.skip("running as root without setpriv: file modes cannot be enforced")
        prefix = [setpriv, f"--bounding-set={DAC_CAPS}", f"--inh-caps={DAC_CAPS}"]
    out = subprocess.run([*prefix, sys.executable, "-c", code, str(root)], capture_output=True,
                         text=True, timeout=60, check=False)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert "not writable" in lines[0], out.stdout
    assert "cannot create bag" in lines[1] and "Permission denied" in lines[1], out.stdout
