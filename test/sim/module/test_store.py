"""Retentive storage, REG_SF resets and write endurance (000 interface table "Storage in
module", "Resetting the register bank", "Retentive registers can be written up to 100,000 times")."""

from __future__ import annotations

import logging
import os
from pathlib import Path

import pytest

from ssi_bridge.exceptions import ParameterError, RegisterWriteError, StorageError
from ssi_bridge.sim.module.bank import ENDURANCE_LIMIT, ENDURANCE_WARNING
from ssi_bridge.protocol.registers import RETENTIVE, SF_LD20, SF_LD48, Reg
from ssi_bridge.sim.module.store import BankSnapshot, MemoryStore, RetentiveStore
from ssi_bridge.sim.module.xn1ssi import Xn1Ssi

WRITES = {  # a non-default value for every writable register
    Reg.REG_PARA1: 0x99020000, Reg.REG_LOWER_LIMIT: 11, Reg.REG_UPPER_LIMIT: 22,
    Reg.REG_OFFSET: 33, Reg.REG_SSI_MASK: 0x80, Reg.REG_CMP1: 44, Reg.REG_CMP2: 55,
}


def write_all(module: Xn1Ssi) -> None:
    for reg, value in WRITES.items():
        module.write_register(reg, value)


def test_retentive_registers_survive_a_restart(tmp_path: Path) -> None:
    # 000 interface table: retentive registers kept, non-retentive (CMP1/2, SF) reset
    store = RetentiveStore(tmp_path / "slot0.json")
    write_all(Xn1Ssi(store=store))
    again = Xn1Ssi(store=RetentiveStore(tmp_path / "slot0.json"))
    for reg, value in WRITES.items():
        expected = value if reg in RETENTIVE else 0
        assert again.read_register(reg) == expected, f"{reg.name} after restart"
    assert again.para1.ssi_code_gray, "restored REG_PARA1 is in force"


def test_missing_file_means_defaults(tmp_path: Path) -> None:
    m = Xn1Ssi(store=RetentiveStore(tmp_path / "none" / "bank.json"))
    assert m.read_register(Reg.REG_UPPER_LIMIT) == 0xFFFFFFFF


@pytest.mark.parametrize("content", [b"", b"{", b'{"format": "x"}', b"\xff\xfe"])
def test_damaged_file_raises_storage_error(tmp_path: Path, content: bytes) -> None:
    path = tmp_path / "bank.json"
    path.write_bytes(content)
    with pytest.raises(StorageError, match="unreadable"):
        Xn1Ssi(store=RetentiveStore(path))


def test_crc_catches_an_edited_value(tmp_path: Path) -> None:
    path = tmp_path / "bank.json"
    Xn1Ssi(store=RetentiveStore(path)).write_register(Reg.REG_OFFSET, 12345)
    path.write_text(path.read_text().replace("12345", "12346"))
    with pytest.raises(StorageError, match="CRC"):
        RetentiveStore(path).load()


def test_failed_save_leaves_old_bank_and_refuses_the_write(tmp_path: Path, monkeypatch) -> None:
    path = tmp_path / "bank.json"
    m = Xn1Ssi(store=RetentiveStore(path))
    m.write_register(Reg.REG_OFFSET, 1)

    def broken_replace(src: object, dst: object) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", broken_replace)
    with pytest.raises(RegisterWriteError, match="storage failed"):
        m.write_register(Reg.REG_OFFSET, 2)
    monkeypatch.undo()
    assert m.read_register(Reg.REG_OFFSET) == 1, "memory does not run ahead of the disk"
    assert RetentiveStore(path).load().values[Reg.REG_OFFSET] == 1
    assert not list(tmp_path.glob(".*.tmp")), "temp file removed"


def test_stale_temp_file_is_ignored_and_removed(tmp_path: Path) -> None:
    path = tmp_path / "bank.json"
    Xn1Ssi(store=RetentiveStore(path)).write_register(Reg.REG_OFFSET, 7)
    (tmp_path / ".bank.json.999.tmp").write_bytes(b'{"half')
    assert Xn1Ssi(store=RetentiveStore(path)).read_register(Reg.REG_OFFSET) == 7
    assert not (tmp_path / ".bank.json.999.tmp").exists()


def test_ld20_resets_all_retentive_registers() -> None:
    # 000 "Resetting the register bank": "LD20" = 6C643230 incl. parameter registers
    m = Xn1Ssi()
    write_all(m)
    m.write_register(Reg.REG_SF, SF_LD20)
    for reg in RETENTIVE:
        assert m.read_register(reg) == Xn1Ssi().read_register(reg), f"LD20 resets {reg.name}"
    assert m.read_register(Reg.REG_CMP1) == 44, "non-retentive registers are not touched"
    assert m.read_register(Reg.REG_SF) == SF_LD20


def test_ld48_keeps_the_parameters() -> None:
    # 000: "LD48" = 6C643438 all retentive registers except the parameter registers
    m = Xn1Ssi()
    write_all(m)
    m.write_register(Reg.REG_SF, SF_LD48)
    assert m.read_register(Reg.REG_PARA1) == WRITES[Reg.REG_PARA1]
    for reg in (Reg.REG_LOWER_LIMIT, Reg.REG_UPPER_LIMIT, Reg.REG_OFFSET, Reg.REG_SSI_MASK):
        assert m.read_register(reg) == Xn1Ssi().read_register(reg), f"LD48 resets {reg.name}"


@pytest.mark.parametrize("value", [0, 1, 0x6C643231, 0x3032646C, 0xFFFFFFFF])
def test_other_sf_values_are_rejected(value: int) -> None:
    m = Xn1Ssi()
    m.write_register(Reg.REG_OFFSET, 9)
    with pytest.raises(RegisterWriteError, match="invalid signature"):
        m.write_register(Reg.REG_SF, value)
    assert m.read_register(Reg.REG_OFFSET) == 9


def test_ld20_clears_err_para() -> None:
    m = Xn1Ssi()
    with pytest.raises(ParameterError):
        m.write_para1(0)
    assert m.diag
    m.write_register(Reg.REG_SF, SF_LD20)
    assert not m.diag, "default parameter set is valid again"


def _worn(writes: int) -> Xn1Ssi:
    counts = {reg: writes for reg in RETENTIVE}
    return Xn1Ssi(store=MemoryStore(BankSnapshot(write_counts=counts)))


def test_write_counter_per_register() -> None:
    # 000: "Retentive registers can be written up to 100,000 times" -> a counter per register
    m = Xn1Ssi()
    for _ in range(3):
        m.write_register(Reg.REG_OFFSET, 1)
    m.write_register(Reg.REG_CMP1, 1)
    counts = {reg: e.writes for reg, e in m.endurance.items()}
    assert counts[Reg.REG_OFFSET] == 3 and counts[Reg.REG_LOWER_LIMIT] == 0
    assert Reg.REG_CMP1 not in counts, "non-retentive registers have no endurance"
    m.write_register(Reg.REG_SF, SF_LD48)
    assert m.endurance[Reg.REG_OFFSET].writes == 4, "a reset rewrites the cell"
    assert m.endurance[Reg.REG_PARA1].writes == 0, "LD48 leaves the parameters"


def test_warning_before_the_limit(caplog) -> None:
    m = _worn(ENDURANCE_WARNING - 1)
    assert not m.endurance[Reg.REG_OFFSET].warning
    with caplog.at_level(logging.WARNING, logger="ssi_bridge.sim.module.bank"):
        m.write_register(Reg.REG_OFFSET, 1)
    assert m.endurance[Reg.REG_OFFSET].warning, "warning from 90,000 writes on"
    assert "REG_OFFSET written 90000 of 100000" in caplog.text


def test_refusal_after_the_limit() -> None:
    m = _worn(ENDURANCE_LIMIT - 1)
    m.write_register(Reg.REG_UPPER_LIMIT, 5)  # the 100,000th write is still accepted
    assert m.endurance[Reg.REG_UPPER_LIMIT].exhausted
    with pytest.raises(RegisterWriteError, match="write endurance exhausted: 100000 of 100000"):
        m.write_register(Reg.REG_UPPER_LIMIT, 6)
    with pytest.raises(ParameterError, match="endurance"):
        _worn(ENDURANCE_LIMIT).write_para1(0x19010000)
    assert m.read_register(Reg.REG_UPPER_LIMIT) == 5
    m.write_register(Reg.REG_CMP1, 6)  # non-retentive registers are not limited


def test_counters_survive_a_restart(tmp_path: Path) -> None:
    store = RetentiveStore(tmp_path / "bank.json")
    m = Xn1Ssi(store=store)
    m.write_register(Reg.REG_OFFSET, 1)
    m.write_register(Reg.REG_OFFSET, 2)
    assert Xn1Ssi(store=store).endurance[Reg.REG_OFFSET].writes == 2
