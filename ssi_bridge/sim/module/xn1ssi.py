"""The XN-1SSI SSI technology module: one cycle, process images, register bank (000 ch. 1-2).

One :meth:`Xn1Ssi.cycle` is one module cycle on the injected clock: acquire one frame (unless
STOP = 1 or ERR_PARA = 1, then STS_STOP = 1), evaluate SSI status bits, comparators, limits
and direction, then serve the register handshake of the current process output image
(000 "Internal registers - read and write operations").  The module never reads the wall
clock and does not care where frames come from (any :class:`SsiReader`).
"""

from __future__ import annotations

import logging
from collections.abc import Callable

from ssi_bridge.exceptions import ParameterError, RegisterReadError, RegisterWriteError
from ssi_bridge.protocol.readout import LineReadout, SsiReader
from ssi_bridge.sim.module import acquisition
from ssi_bridge.sim.module.bank import Endurance, RegisterBank
from ssi_bridge.protocol.diagnostics import Diag
from ssi_bridge.protocol.images import (
    CmpControl, CmpStatus, ModuleStatus, ProcessInput, ProcessOutput, encode_input,
)
from ssi_bridge.protocol.para1 import Para1
from ssi_bridge.protocol.registers import (
    HW_VERSION, MAGIC_NO, REGISTER_COUNT, SW_VERSION, VALUE_MAX, Reg, describe_refusal,
    validate_para1,
)
from ssi_bridge.sim.module.store import BankStore

logger = logging.getLogger(__name__)

# Status bits as plain ints: cycle() and the gateway's per-SYNC reads combine them on every
# cycle, where each IntFlag operation (&, |, construction) would be a Python-level call. The
# IntFlag types stay the public face (status, diag); internal state is ints.
_SSI_DIAG, _ERR_SSI, _STS_OFLW, _STS_UFLW, _ERR_PARA, _STS_STOP = map(int, (
    ModuleStatus.SSI_DIAG, ModuleStatus.ERR_SSI, ModuleStatus.STS_OFLW, ModuleStatus.STS_UFLW,
    ModuleStatus.ERR_PARA, ModuleStatus.STS_STOP))
#: diagnostics byte = process input byte 7 bits 0-4 (000 chapter 2 "Diagnostics")
_DIAG_BITS = 0x1F
_STS_UP, _STS_DN = int(CmpStatus.STS_UP), int(CmpStatus.STS_DN)
#: comparator units: (register, EN_CMPx, CLR_CMPx, shift of STS/FLAG/REL_CMPx in byte 6)
_CMP_UNITS = ((0, Reg.REG_CMP1, int(CmpControl.EN_CMP1), int(CmpControl.CLR_CMP1), 0),
              (1, Reg.REG_CMP2, int(CmpControl.EN_CMP2), int(CmpControl.CLR_CMP2), 3))
_REG_OFFSET, _REG_SSI_MASK = Reg.REG_OFFSET, Reg.REG_SSI_MASK
_REG_LOWER_LIMIT, _REG_UPPER_LIMIT = Reg.REG_LOWER_LIMIT, Reg.REG_UPPER_LIMIT
#: every value of process input bytes 6 / 7 and of the diagnostics byte as its IntFlag,
#: built once, so handing the flag types to readers costs an index instead of a construction
_CMP_FLAGS: tuple[CmpStatus, ...] = tuple(CmpStatus(v) for v in range(256))
_STS_FLAGS: tuple[ModuleStatus, ...] = tuple(ModuleStatus(v) for v in range(256))
_DIAG_FLAGS: tuple[Diag, ...] = tuple(Diag(v) for v in range(_DIAG_BITS + 1))
#: why a process-data read of address 0..63 is refused (None = readable), from the 000
#: interface table via describe_refusal, looked up once per address instead of once per cycle
_READ_REFUSAL: tuple[str | None, ...] = tuple(
    describe_refusal(addr, write=False) for addr in range(REGISTER_COUNT))


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
        self._control = 0  # process output byte 6 (EN_CMPx / CLR_CMPx) as an int
        # figures of the REG_PARA1 set in force, derived once per set (000 Table 19)
        self._para: Para1 | None = None
        self._n_bits = 0
        self._rate_hz = 0.0
        self._width = 0
        self._last_readout: LineReadout | None = None
        self._frame = 0
        self._gray = 0
        self._value: int | None = None
        self._pos = 0
        self._err_ssi = False
        self._ssi_sts = 0
        self._ssi_diag = False
        self._cmp = 0  # process input byte 6 (CmpStatus bits)
        self._flags = [False, False]
        self._oflw = self._uflw = False
        self._stop_latched = False
        self._wr_akn = self._wr_accept = False
        self._rd_adr, self._rd_abort, self._rd_data = 0, False, 0  # REG_RD_ADR echo, ...
        self._image: bytes | None = None  # the encoded input image of this cycle
        self._image_err_para = False  # ERR_PARA when it was encoded

    # -- process data ---------------------------------------------------------------------
    def set_process_output(self, image: bytes) -> None:
        """Store the 8-byte process output image the next :meth:`cycle` acts on."""
        out = ProcessOutput.decode(bytes(image))
        self._out = out
        self._control = int(out.cmp)

    def process_input(self) -> bytes:
        """The 8-byte process input image (000 "Process input").

        Encoded once per cycle: only :meth:`cycle` changes the module's own state, and the one
        outside input, ERR_PARA (a parameter set written at any time), is part of the key.
        """
        err_para = self.bank.err_para
        image = self._image
        if image is None or self._image_err_para != err_para:
            image = self._image = encode_input(
                self._rd_data, self._rd_adr, self._rd_abort, self._wr_akn, self._wr_accept,
                self._ssi_sts, self._cmp, self._sts())
            self._image_err_para = err_para
        return image

    def _sts(self) -> int:
        """Process input byte 7 as an int (000 "Process input"; STS_STOP also on ERR_PARA)."""
        err_para = self.bank.err_para
        return ((_SSI_DIAG if self._ssi_diag else 0) | (_ERR_SSI if self._err_ssi else 0)
                | (_STS_OFLW if self._oflw else 0) | (_STS_UFLW if self._uflw else 0)
                | (_ERR_PARA if err_para else 0)
                | (_STS_STOP if self._stop_latched or err_para else 0))

    @property
    def status(self) -> ProcessInput:
        """The decoded process input image."""
        return ProcessInput(reg_rd_data=self._rd_data, reg_rd_adr=self._rd_adr,
                            reg_rd_abort=self._rd_abort, reg_wr_akn=self._wr_akn,
                            reg_wr_accept=self._wr_accept, ssi_sts=self._ssi_sts,
                            cmp=_CMP_FLAGS[self._cmp], sts=_STS_FLAGS[self._sts()])

    @property
    def diag(self) -> Diag:
        """The diagnostics byte (000 chapter 2 "Diagnostics"), also REG_DIAG1."""
        return _DIAG_FLAGS[self._sts() & _DIAG_BITS]

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
        """Run one module cycle at time ``t`` (s) on the current process output image.

        Called for every slot on every SYNC, so the state stays ints and the REG_PARA1
        figures (frame length, bit rate, word width) are derived once per accepted set.
        """
        self._image = None  # first: even a cycle that fails half-way must not leave it stale
        out = self._out
        bank = self.bank
        stop = out.stop
        self._stop_latched = stop
        up = down = False
        reader = self.reader
        if not (stop or bank.err_para) and reader is not None:
            para = bank.para
            if para is not self._para:
                self._use_para(para)
            readout = reader.read(t, self._n_bits, self._rate_hz)
            self._last_readout = readout
            got = acquisition.extract(readout, para)
            self._frame = got.frame
            ok = got.ok
            self._err_ssi = not ok
            if ok:
                value = got.value
                up, down = acquisition.direction(self._value, value, self._width)
                self._value, self._gray = value, got.gray
        if self._value is not None:
            self._pos = (self._value - bank.values[_REG_OFFSET]) & VALUE_MAX
        self._evaluate(up, down)
        self._handshake(out)

    def _use_para(self, para: Para1) -> None:
        """Derive what a cycle needs from a new REG_PARA1 set (000 Table 19)."""
        self._para = para
        self._n_bits = para.ssi_frame_len
        self._rate_hz = float(para.bit_rate_hz)
        self._width = para.value_bits

    def _evaluate(self, up: bool, down: bool) -> None:
        """SSI status bits, comparators, limits, direction (000 chapter 1, Tables 1-3)."""
        values = self.bank.values
        pos = self._pos
        self._ssi_sts, self._ssi_diag = acquisition.ssi_status(self._frame,
                                                               values[_REG_SSI_MASK])
        control = self._control
        cmp = (_STS_UP if up else 0) | (_STS_DN if down else 0)
        flags = self._flags
        for i, reg, en, clr, shift in _CMP_UNITS:
            if control & en:
                sts, flag, rel = acquisition.compare(pos, values[reg], enabled=True,
                                                     clear=bool(control & clr), flag=flags[i])
                flags[i] = flag
                cmp |= (sts | flag << 1 | rel << 2) << shift
            else:  # EN_CMPx = 0: STS/FLAG/REL_CMPx 0 and the latched flag forgotten (compare)
                flags[i] = False
        self._cmp = cmp
        self._oflw, self._uflw = acquisition.limits(pos, values[_REG_LOWER_LIMIT],
                                                    values[_REG_UPPER_LIMIT])

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
        adr = out.reg_rd_adr  # 0..63: the image's 6-bit field
        self._rd_adr = adr
        if _READ_REFUSAL[adr] is None:
            self._rd_abort, self._rd_data = False, self._read(adr)
        else:
            self._rd_abort, self._rd_data = True, 0

    # -- register bank --------------------------------------------------------------------
    def read_register(self, addr: int) -> int:
        """Read register ``addr`` as the process input would (raises RegisterReadError)."""
        reason = describe_refusal(addr, write=False)
        if reason is not None:
            raise RegisterReadError(addr, reason)
        return self._read(addr)

    def _read(self, addr: int) -> int:
        """Value of the readable register ``addr``: computed live or from the bank."""
        live = _LIVE_REGISTERS.get(addr)
        return live(self) if live is not None else self.bank.value(Reg(addr))

    def write_register(self, addr: int, value: int) -> None:
        """Write register ``addr`` as the process output would (raises RegisterWriteError).

        :param addr: the register
        :param value: its new value
        """
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

    def inject_parameter_error(self, value: int | None = None) -> str:
        """Simulation: an invalid REG_PARA1 set reaches the parameter interface; the reason.

        Bypasses every master-side check, so ERR_PARA = 1 (and STS_STOP = 1, diagnostics bit
        4, EMCY 0x7000 byte 5 = 0x10 "Parameter error", 000 "Additional emergencies") can be
        exercised end to end.  Default: the set in force with the reserved SSI_BIT_RATE 8
        (000 Table 19: 8..15 reserved).  REG_PARA1 keeps its valid value, as the manual says
        of a rejected set; :meth:`clear_parameter_error` sends that valid set again.

        :param value: the invalid REG_PARA1 (default: one that breaks a rule of 000 Table 19)
        :raises ValueError: ``value`` is a valid set (it would not raise ERR_PARA)
        """
        if value is None:
            value = (self.bank.para.encode() & ~0x000F0000) | (8 << 16)
        reason = validate_para1(value)
        if reason is None:
            raise ValueError(f"REG_PARA1 0x{value:08X} is valid: it cannot raise ERR_PARA")
        try:
            self.bank.write_para1(value)
        except ParameterError:
            pass
        return reason

    def clear_parameter_error(self) -> None:
        """Simulation: send the REG_PARA1 set in force again, which clears ERR_PARA (000)."""
        self.bank.write_para1(self.bank.para.encode())

    @staticmethod
    def validate_para1(value: int) -> str | None:
        """Why ``value`` would be refused as REG_PARA1 (None = valid); writes nothing."""
        return validate_para1(value)


#: registers the module computes instead of storing them (000 interface table), by address
_LIVE_REGISTERS: dict[int, Callable[[Xn1Ssi], int]] = {
    Reg.REG_SSI_POS: lambda m: m._pos,
    Reg.REG_MAGIC_NO: lambda m: MAGIC_NO,
    Reg.REG_HW_VER: lambda m: HW_VERSION,
    Reg.REG_SW_VER: lambda m: SW_VERSION,
    Reg.REG_WR_ADR: lambda m: m._out.reg_wr_adr,
    Reg.REG_RD_ADR: lambda m: m._out.reg_rd_adr,
    Reg.REG_DIAG1: lambda m: int(m.diag),
    Reg.REG_GRAY_POS: lambda m: m._gray,
    Reg.REG_SSI_FRAME: lambda m: m._frame,
}
