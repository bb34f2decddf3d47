"""A crash while storing retentive registers never leaves a half-written bank
(000 interface table "Storage in module: Retentive"; docs/module.md "Retentive storage").

A writer process saves bank after bank (REG_OFFSET = 1, 2, 3, ...) and reports each completed
save on stdout; the test kills it with SIGKILL after a random number of reports, i.e. at a
random point of a later save, many times, and then starts a module on the file.
"""

from __future__ import annotations

import random
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from ssi_bridge.protocol.registers import Reg
from ssi_bridge.sim.module.xn1ssi import Xn1Ssi
from ssi_bridge.sim.module.store import RetentiveStore

REPO = Path(__file__).resolve().parents[3]
WRITER = """
import sys
from ssi_bridge.protocol.registers import RETENTIVE, REGISTERS, Reg
from ssi_bridge.sim.module.store import BankSnapshot, RetentiveStore
store = RetentiveStore(sys.argv[1], fsync=sys.argv[2] == "1")
i = int(sys.argv[3])
while True:
    i += 1
    values = {r: REGISTERS[r].default for r in RETENTIVE}
    values[Reg.REG_OFFSET] = i
    values[Reg.REG_LOWER_LIMIT] = i  # two registers: a torn bank would show them differ
    store.save(BankSnapshot(values, {r: i for r in RETENTIVE}))
    print(i, flush=True)
"""
KILLS = 30


def _kill_during_saves(path: Path, fsync: bool, start: int, reports: int) -> int:
    """Run the writer until it has reported ``reports`` saves, SIGKILL it, return the last report.

    The writer keeps saving while the kill is on its way, so the saves it reported before
    dying are drained from the pipe too: the bank may hold the last of them or the one after.
    """
    proc = subprocess.Popen([sys.executable, "-c", WRITER, str(path), "1" if fsync else "0",
                             str(start)], stdout=subprocess.PIPE, text=True, cwd=REPO)
    last = start
    try:
        assert proc.stdout is not None
        for _ in range(reports):
            line = proc.stdout.readline()
            assert line, f"writer died early (rc {proc.poll()})"
            last = int(line)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL
    assert proc.stdout is not None
    for line in proc.stdout.read().split():
        last = int(line)
    return last


@pytest.mark.parametrize("fsync", [False, True], ids=["no-fsync", "fsync"])
def test_kill_at_random_points_leaves_old_or_new_bank(tmp_path: Path, fsync: bool) -> None:
    rng = random.Random(4 + fsync)
    path = tmp_path / "bank.json"
    stored = 0
    for kill in range(KILLS // 2):
        last_reported = _kill_during_saves(path, fsync, stored, rng.randint(1, 40))
        module = Xn1Ssi(store=RetentiveStore(path))  # must not raise StorageError
        offset = module.read_register(Reg.REG_OFFSET)
        assert module.read_register(Reg.REG_LOWER_LIMIT) == offset, f"kill {kill}: torn bank"
        assert offset in (last_reported, last_reported + 1), (
            f"kill {kill}: bank holds {offset}, last completed save {last_reported}: "
            "neither the old nor the new value")
        assert module.endurance[Reg.REG_OFFSET].writes == offset, "counters saved with the values"
        stored = offset
    assert not list(tmp_path.glob(".*.tmp")), "start-up removed the temp files of killed saves"
