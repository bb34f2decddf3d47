"""The XN-1SSI SSI technology module: one cycle, process images, register bank (000 ch. 1-2).

One :meth:`Xn1Ssi.cycle` is one module cycle on the injected clock: acquire one frame (unless
STOP = 1 or ERR_PARA = 1, then STS_STOP = 1), evaluate SSI status bits, comparators, limits
and direction, then serve the register handshake of the current process output image
(000 "Internal registers - read and write operations").  The module never reads the wall
clock and does not care where frames come from (any :class:`SsiReader`).
"""

from __future__ import annotations

import logging

from ssi_bridge.exceptions import RegisterReadError, RegisterWriteError
from ssi_bridge.line.readout import LineReadout, SsiReader
from ssi_bridge.module import acquisition
from ssi_bridge.module.bank import Endurance, RegisterBank
from ssi_bridge.module.diagnostics import Diag
from ssi_bridge.module.images import (
    CmpControl, CmpStatus, ModuleStatus, ProcessInput, ProcessOutput,
)
from ssi_bridge.module.para1 import Para1
from ssi_bridge.module.registers import (
    HW_VERSION, MAGIC_NO, REGISTER_COUNT, SW_VERSION, VALUE_MAX, Reg, describe_refusal,
    validate_para1,
)
from ssi_bridge.module.store import BankStore

logger = logging.getLogger(__name__)


class Xn1Ssi:
    """Model of one XN-1SSI module in slot ``slot`` of a station.

    :param reader: the SSI line (or any scripted reader); None = no encoder attached
    :param store: retentive storage of REG_PARA1, limits, offset and mask (None = memory only)
    :param slot: module slot number (EMCY byte 3, gateway subindex)
    :raises StorageError: the store exists but cannot be read
    """

    def __init__(self, reader: SsiReader | None = None, *, store: BankStore | None = None,
                 slot: int = 0) -> None:
        self.reader = reader
        self.slot = slot
        self.bank = RegisterBank(store, slot)
        self._out = ProcessOutput()
        self._last_readout: LineReadout | None = None
        self._frame = 0
        self._gray = 0
        self._value: int | None = None
        self._pos = 0
        self._err_ssi = False
        self._ssi_sts = 0
        self._ssi_diag = False
        self._cmp = CmpStatus(0)
        self._flags = [False, False]
        self._oflw = self._uflw = False
        self._stop_latched = False
        self._wr_akn = self._wr_accept = False
        self._rd = (0, False, 0)  # REG_RD_ADR echo, REG_RD_ABORT, REG_RD_DATA

    # -- process data ---------------------------------------------------------------------
    def set_process_output(self, image: bytes) -> None:
        """Store the 8-byte process output image the next :meth:`cycle` acts on."""
        self._out = ProcessOutput.decode(bytes(image))

    def process_input(self) -> bytes:
        """The 8-byte process input image (000 "Process input")."""
        return self.status.encode()

    @property
    def status(self) -> ProcessInput:
        """The decoded process input image."""
        sts = ModuleStatus(0)
        err_para = self.bank.err_para
        for flag, on in ((ModuleStatus.SSI_DIAG, self._ssi_diag),
                         (ModuleStatus.ERR_SSI, self._err_ssi),
                         (ModuleStatus.STS_OFLW, self._oflw), (ModuleStatus.STS_UFLW, self._uflw),
                         (ModuleStatus.ERR_PARA, err_para),
                         (ModuleStatus.STS_STOP, self._stop_latched or err_para)):
            if on:
                sts |= flag
        adr, abort, data = self._rd
        return ProcessInput(reg_rd_data=data, reg_rd_adr=adr, reg_rd_abort=abort,
                            reg_wr_akn=self._wr_akn, reg_wr_accept=self._wr_accept,
                            ssi_sts=self._ssi_sts, cmp=self._cmp, sts=sts)

    @property
    def diag(self) -> Diag:
        """The diagnostics byte (000 chapter 2 "Diagnostics"), also REG_DIAG1."""
        return Diag(int(self.status.sts) & 0x1F)

    @property
    def last_readout(self) -> LineReadout | None:
        """The readout of the last acquisition (None before the first one)."""
        return self._last_readout

    @property
    def latch_time(self) -> float | None:
        """Latch time (s) of the frame behind REG_SSI_POS, None before the first frame."""
        return self._last_readout.latch_time if self._last_readout else None

    @property
    def ssi_pos(self) -> int:
        """REG_SSI_POS as unsigned 32-bit (read it as Integer32 for object 0x6820)."""
        return self._pos

    @property
    def endurance(self) -> dict[Reg, Endurance]:
        """Write counters of the retentive registers (000: 100,000 writes), for diagnostics."""
        return self.bank.endurance()

    @property
    def para1(self) -> Para1:
        """The REG_PARA1 set in force."""
        return self.bank.para

    # -- one cycle ------------------------------------------------------------------------
    def cycle(self, t: float) -> None:
        """Run one module cycle at time ``t`` (s) on the current process output image."""
        out = self._out
        para = self.bank.para
        self._stop_latched = out.stop
        moved = (False, False)
        if not (out.stop or self.bank.err_para) and self.reader is not None:
            readout = self.reader.read(t, para.ssi_frame_len, float(para.bit_rate_hz))
            self._last_readout = readout
            got = acquisition.extract(readout, para)
            self._frame = got.frame
            self._err_ssi = not got.ok
            if got.ok:
                moved = acquisition.direction(self._value, got.value, para.value_bits)
                self._value, self._gray = got.value, got.gray
        if self._value is not None:
            self._pos = (self._value - self.bank.value(Reg.REG_OFFSET)) & VALUE_MAX
        self._evaluate(out, moved)
        self._handshake(out)

    def _evaluate(self, out: ProcessOutput, moved: tuple[bool, bool]) -> None:
        """SSI status bits, comparators, limits, direction (000 chapter 1, Tables 1-3)."""
        bank = self.bank
        mask = bank.value(Reg.REG_SSI_MASK)
        self._ssi_sts, self._ssi_diag = acquisition.ssi_status(self._frame, mask)
        cmp = CmpStatus(0)
        units = ((Reg.REG_CMP1, CmpControl.EN_CMP1, CmpControl.CLR_CMP1, 0),
                 (Reg.REG_CMP2, CmpControl.EN_CMP2, CmpControl.CLR_CMP2, 3))
        for i, (reg, en, clr, shift) in enumerate(units):
            sts, flag, rel = acquisition.compare(self._pos, bank.value(reg),
                                                 enabled=en in out.cmp, clear=clr in out.cmp,
                                                 flag=self._flags[i])
            self._flags[i] = flag
            cmp |= CmpStatus((sts | flag << 1 | rel << 2) << shift)
        if moved[0]:
            cmp |= CmpStatus.STS_UP
        if moved[1]:
            cmp |= CmpStatus.STS_DN
        self._cmp = cmp
        self._oflw, self._uflw = acquisition.limits(
            self._pos, bank.value(Reg.REG_LOWER_LIMIT), bank.value(Reg.REG_UPPER_LIMIT))

    def _handshake(self, out: ProcessOutput) -> None:
        """Register write then read handshake (000 "Internal registers", "Process output")."""
        if not out.reg_wr:
            self._wr_akn = self._wr_accept = False
        elif not self._wr_akn:
            self._wr_akn = True
            try:
                self.write_register(out.reg_wr_adr, out.reg_wr_data)
                self._wr_accept = True
            except RegisterWriteError as err:
                logger.info("slot %d: process-data write refused: %s", self.slot, err)
                self._wr_accept = False
        try:
            self._rd = (out.reg_rd_adr, False, self.read_register(out.reg_rd_adr))
        except RegisterReadError:
            self._rd = (out.reg_rd_adr, True, 0)

    # -- register bank --------------------------------------------------------------------
    def read_register(self, addr: int) -> int:
        """Read register ``addr`` as the process input would (raises RegisterReadError)."""
        reason = describe_refusal(addr, write=False)
        if reason is not None:
            raise RegisterReadError(addr, reason)
        live = {
            Reg.REG_SSI_POS: self._pos, Reg.REG_MAGIC_NO: MAGIC_NO, Reg.REG_HW_VER: HW_VERSION,
            Reg.REG_SW_VER: SW_VERSION, Reg.REG_WR_ADR: self._out.reg_wr_adr,
            Reg.REG_RD_ADR: self._out.reg_rd_adr, Reg.REG_DIAG1: int(self.diag),
            Reg.REG_GRAY_POS: self._gray, Reg.REG_SSI_FRAME: self._frame,
        }
        reg = Reg(addr)
        return live[reg] if reg in live else self.bank.value(reg)

    def write_register(self, addr: int, value: int) -> None:
        """Write register ``addr`` as the process output would (raises RegisterWriteError)."""
        if not 0 <= addr < REGISTER_COUNT:
            raise RegisterWriteError(addr, f"out of range 0..{REGISTER_COUNT - 1}")
        reason = describe_refusal(addr, write=True)
        if reason is not None:
            raise RegisterWriteError(addr, reason)
        self.bank.write(Reg(addr), value)

    def write_para1(self, value: int) -> None:
        """The parameter interface: take a REG_PARA1 set (raises ParameterError).

        An invalid set is rejected and raises ERR_PARA = 1 (so STS_STOP = 1) until a valid set
        arrives; REG_PARA1 keeps the last accepted value (000 "Error detection": ERR_PARA is
        a "non-retentive error message, and rejected parameter set with it").
        """
        self.bank.write_para1(value)

    @staticmethod
    def validate_para1(value: int) -> str | None:
        """Why ``value`` would be refused as REG_PARA1 (None = valid); writes nothing."""
        return validate_para1(value)
