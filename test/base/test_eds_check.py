"""config/xn_gw_canopen.eds: what `write_eds` generates, and accepted by lely's CiA 306 checker.

``dcfchk`` (PyPI ``dcf-tools``, a test dependency in requirements.in) is the checker of the
lely tool family that ros2_canopen builds its bus configurations with. Before, it rejected the
file with 5 warnings on the simulation-only objects 0x4000-0x4003 (a ``Description=`` key,
which CiA 306 does not define, and a REAL32 ``DefaultValue=0.0``, which CiA 306 writes as an
integer).
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from ssi_bridge.base.od import write_eds

EDS = Path(__file__).resolve().parents[2] / "config" / "xn_gw_canopen.eds"


def _dcfchk() -> str:
    beside = Path(sys.executable).parent / "dcfchk"
    found = str(beside) if beside.is_file() else shutil.which("dcfchk")
    if found is None:
        pytest.skip("dcfchk not installed: pip install dcf-tools==2.4.2 (requirements.in)")
    return found


def test_the_eds_file_is_the_generated_one(tmp_path: Path) -> None:
    fresh = tmp_path / "fresh.eds"
    write_eds(str(fresh))
    assert fresh.read_text(encoding="ascii") == EDS.read_text(encoding="ascii"), (
        "config/xn_gw_canopen.eds is out of date: regenerate it with "
        "python -c \"from ssi_bridge.base.od import write_eds; "
        "write_eds('config/xn_gw_canopen.eds')\"")


@pytest.mark.parametrize("node_id", [1, 3, 127])
def test_dcfchk_accepts_the_eds(node_id: int) -> None:
    run = subprocess.run([_dcfchk(), "-n", str(node_id), str(EDS)], capture_output=True,
                         text=True, timeout=60)
    assert run.returncode == 0 and "Warning" not in run.stderr, run.stderr[-3000:]


def test_dcfchk_can_fail(tmp_path: Path) -> None:
    """The check has teeth: the form the file had before is refused."""
    bad = tmp_path / "bad.eds"
    text = EDS.read_text(encoding="ascii")
    bad.write_text(text.replace("[4000]\nParameterName=SIM fault rate\n",
                                "[4000]\nParameterName=SIM fault rate\nDescription=x\n"),
                   encoding="ascii")
    run = subprocess.run([_dcfchk(), "-n", "3", str(bad)], capture_output=True, text=True,
                         timeout=60)
    assert run.returncode != 0 and "Description" in run.stderr, run.stderr[-3000:]
