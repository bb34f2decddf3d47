"""The writable part of the XN-1SSI register bank: values, REG_PARA1, REG_SF, endurance.

000 interface table: REG_SF, REG_CMP1, REG_CMP2 are writable and non-retentive (0 after a
restart); REG_PARA1, REG_LOWER_LIMIT, REG_UPPER_LIMIT, REG_OFFSET, REG_SSI_MASK are writable
and retentive (restored from the store at start).  "Retentive registers can be written up to
100,000 times": every accepted write of a retentive register (including a reset by LD20/LD48)
counts; from :data:`ENDURANCE_WARNING` writes on a warning is logged and reported, and a write
past :data:`ENDURANCE_LIMIT` is refused.  A retentive write is stored before it takes effect,
so the bank in memory never runs ahead of the bank on disk.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

from ssi_bridge.exceptions import ParameterError, RegisterWriteError, StorageError
from ssi_bridge.protocol.para1 import Para1, validate_para1
from ssi_bridge.protocol.registers import (
    PARAMETER_REGISTERS, REGISTERS, RETENTIVE, SF_LD20, SF_LD48, VALUE_MAX, Reg,
)
from ssi_bridge.sim.module.store import BankSnapshot, BankStore

logger = logging.getLogger(__name__)

#: writes a retentive register survives (000 interface table note)
ENDURANCE_LIMIT = 100_000
#: from this many writes on the endurance is reported as a warning
ENDURANCE_WARNING = 90_000


@dataclass(frozen=True)
class Endurance:
    """Write-endurance state of one retentive register."""

    reg: Reg
    writes: int
    limit: int = ENDURANCE_LIMIT

    @property
    def warning(self) -> bool:
        """True from ENDURANCE_WARNING writes on."""
        return self.writes >= ENDURANCE_WARNING

    @property
    def exhausted(self) -> bool:
        """True when no further write will be accepted."""
        return self.writes >= self.limit


class RegisterBank:
    """Values of the writable registers, the REG_PARA1 set in force and ERR_PARA.

    :param store: where the retentive registers are kept (default: nothing kept)
    :param slot: the module's slot (named in messages)
    """

    def __init__(self, store: BankStore | None = None, slot: int = 0) -> None:
        self.store = store
        self.slot = slot
        self._values: dict[Reg, int] = {r: i.default for r, i in REGISTERS.items() if i.writable}
        #: read-only live view of the writable registers' values (the module's per-cycle reads)
        self.values: Mapping[Reg, int] = MappingProxyType(self._values)
        self._counts: dict[Reg, int] = {r: 0 for r in RETENTIVE}
        snapshot = store.load() if store is not None else None
        if snapshot is not None:
            self._values.update(snapshot.values)
            self._counts.update(snapshot.write_counts)
        self.para = Para1.decode(self._values[Reg.REG_PARA1])
        problem = self.para.problem()
        #: ERR_PARA: the present parameter set was rejected (000 "Error detection")
        self.err_para = problem is not None
        if problem:
            logger.error("slot %d: stored REG_PARA1 0x%08X invalid: %s", slot,
                         self._values[Reg.REG_PARA1], problem)

    def value(self, reg: Reg) -> int:
        """Current value of a writable register.

        :param reg: a writable register
        """
        return self._values[reg]

    def endurance(self) -> dict[Reg, Endurance]:
        """Write counters of every retentive register (for diagnostics)."""
        return {reg: Endurance(reg, n) for reg, n in self._counts.items()}

    def write(self, reg: Reg, value: int) -> None:
        """Write a writable register through the process-data rules (raises RegisterWriteError).

        :param reg: a writable register
        :param value: its new value
        :raises RegisterWriteError: a value out of range
        :raises ParameterError: REG_PARA1 with an invalid parameter set (ERR_PARA is set)
        """
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= VALUE_MAX:
            raise RegisterWriteError(reg, f"value {value!r} out of range 0..0x{VALUE_MAX:08X}")
        if reg is Reg.REG_SF:
            self._special_function(value)
        elif reg is Reg.REG_PARA1:
            problem = validate_para1(value)
            if problem:
                raise ParameterError(reg, f"invalid parameter set: {problem}")
            self._store({reg: value})
            self._accept_para(value)
        elif REGISTERS[reg].retentive:
            self._store({reg: value})
        else:
            self._values[reg] = value

    def write_para1(self, value: int) -> None:
        """Parameter interface: an invalid set sets ERR_PARA and raises ParameterError.

        :param value: the new REG_PARA1
        """
        problem = validate_para1(value)
        if problem:
            self.err_para = True
            logger.warning("slot %d: parameter set 0x%08X rejected (ERR_PARA): %s",
                           self.slot, value & VALUE_MAX, problem)
            raise ParameterError(Reg.REG_PARA1, problem)
        try:
            self._store({Reg.REG_PARA1: value})
        except RegisterWriteError as err:
            raise ParameterError(Reg.REG_PARA1, err.reason) from err
        self._accept_para(value)

    def _accept_para(self, value: int) -> None:
        self.para = Para1.decode(value)
        if self.err_para:
            logger.info("slot %d: valid parameter set 0x%08X, ERR_PARA cleared", self.slot, value)
        self.err_para = False

    def _special_function(self, value: int) -> None:
        """REG_SF (000 "Resetting the register bank"): LD20 / LD48, anything else refused."""
        if value == SF_LD20:
            targets = RETENTIVE
        elif value == SF_LD48:
            targets = tuple(r for r in RETENTIVE if r not in PARAMETER_REGISTERS)
        else:
            raise RegisterWriteError(
                Reg.REG_SF, f"invalid signature 0x{value:08X} (LD20 = 0x{SF_LD20:08X} resets all "
                f"retentive registers, LD48 = 0x{SF_LD48:08X} all but the parameters)")
        self._store({reg: REGISTERS[reg].default for reg in targets})
        if Reg.REG_PARA1 in targets:
            self._accept_para(REGISTERS[Reg.REG_PARA1].default)
        self._values[Reg.REG_SF] = value
        logger.info("slot %d: REG_SF 0x%08X reset %s", self.slot, value,
                    ", ".join(r.name for r in targets))

    def _store(self, changes: dict[Reg, int]) -> None:
        """Count, persist, then apply writes of retentive registers (all or nothing)."""
        for reg in changes:
            if self._counts[reg] >= ENDURANCE_LIMIT:
                raise RegisterWriteError(
                    reg, f"write endurance exhausted: {self._counts[reg]} of "
                    f"{ENDURANCE_LIMIT} writes of this retentive register used")
        counts = dict(self._counts)
        for reg in changes:
            counts[reg] += 1
        values = {reg: changes.get(reg, self._values[reg]) for reg in RETENTIVE}
        if self.store is not None:
            try:
                self.store.save(BankSnapshot(values, counts))
            except StorageError as err:
                raise RegisterWriteError(next(iter(changes)), f"storage failed: {err}") from err
        self._values.update(changes)
        self._counts = counts
        for reg in changes:
            if counts[reg] == ENDURANCE_WARNING or counts[reg] == ENDURANCE_LIMIT:
                logger.warning("slot %d: %s written %d of %d times", self.slot, reg.name,
                               counts[reg], ENDURANCE_LIMIT)
