"""Serve the encoder objects of Table 16 and the process-image objects from the modules.

canopen's ``LocalNode`` asks its read callbacks first and falls back to the values written
over SDO (``data_store``) or the dictionary default; so live objects are answered here and
"no function" objects (5800, 5808, 5810-5823, 6B30, 6800) simply keep what was written.
A refused write raises ``SdoAbortedError``, which canopen's ``SdoServer`` sends as the abort.
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from canopen.objectdictionary import ODVariable
from canopen import SdoAbortedError

from ssi_bridge.exceptions import ParameterError, RegisterWriteError
from ssi_bridge.protocol.aborts import SdoAbort
from ssi_bridge.protocol.dictionary import PROCESS_INPUT, PROCESS_OUTPUT
from ssi_bridge.protocol.diagnostics import cam_state, to_int32
from ssi_bridge.protocol.images import CmpControl, CmpStatus, ModuleStatus, ProcessInput
from ssi_bridge.protocol.registers import Reg

if TYPE_CHECKING:
    from ssi_bridge.sim.module.xn1ssi import Xn1Ssi

logger = logging.getLogger(__name__)

#: objects that read/write one module register (Table 16 "Name in the I/O Assistant")
REGISTER_OBJECTS: dict[int, Reg] = {
    0x5801: Reg.REG_PARA1, 0x5840: Reg.REG_SSI_MASK, 0x6810: Reg.REG_OFFSET,
    0x6820: Reg.REG_SSI_POS, 0x6B10: Reg.REG_CMP2, 0x6B20: Reg.REG_CMP1,
    0x6C01: Reg.REG_LOWER_LIMIT, 0x6C02: Reg.REG_UPPER_LIMIT,
}
#: Integer32 objects: the 32-bit register is read as two's complement (Tables 39-40, 47-48)
SIGNED_OBJECTS = frozenset({0x6810, 0x6820, 0x6B10, 0x6B20, 0x6C01, 0x6C02})
#: 0x6810 "Preset value for multi-sensor devices": "The content of this object is added to the
#: value of the SSI encoder. The resulting value is stored in object 6820" (000, object
#: 6810hex). The module subtracts REG_OFFSET (000 ch. 1 "Offset function": REG_SSI_POS = SSI
#: encoder - REG_OFFSET), so the gateway keeps REG_OFFSET = -(0x6810) and reads 0x6810 back as
#: -REG_OFFSET: both sentences of 000 hold (docs/canopen.md "Preset: object 0x6810")
PRESET = 0x6810
#: a write of any value resets FLAG_CMP1/2 unless still matching (000 on 5803 and 5805)
FLAG_RESET_OBJECTS = frozenset({0x5803, 0x5805})
CAM_ENABLE, CAM_POLARITY = 0x6B01, 0x6B02
#: DS406 area state bits (object 6400, here 6C00): out of range, overflow, underflow
AREA_OUT, AREA_OVER, AREA_UNDER = 0x01, 0x02, 0x04
#: every ARRAY object answered from the modules (sub 1..n = slot 1..n)
SERVED = frozenset({PROCESS_INPUT, PROCESS_OUTPUT, *REGISTER_OBJECTS, 0x5802, 0x5803, 0x5804,
                    0x5805, 0x5806, 0x6B00, CAM_ENABLE, CAM_POLARITY, 0x6C00})
_IDLE_OUTPUT = bytes(8)
#: objects decoded from the process input image (``module.status``), 6C00 = DS406 area state
_STATUS_OBJECTS = frozenset({0x5802, 0x5803, 0x5805, 0x6C00})
#: 0x6820 on the wire: REG_SSI_POS as Integer32, little endian (CiA 301 7.1.2.4)
POSITION_STRUCT = struct.Struct("<I")
#: REG_SSI_POS object (000 Table 40)
POSITION = 0x6820


class EncoderObjects:
    """Map object (index, slot) onto :class:`Xn1Ssi` calls; subindex = slot number (1-based).

    :param modules: the station's modules, slot 1 first
    """

    def __init__(self, modules: Sequence[Xn1Ssi]) -> None:
        self.modules = list(modules)
        #: the process output image last written by the master, per slot
        self.outputs = [_IDLE_OUTPUT] * len(self.modules)
        #: CLR_CMPx bits to pulse in the next cycle (flag reset via 5803/5805), per slot
        self.pending_clear = [CmpControl(0)] * len(self.modules)
        self._clear_armed = False  # any pending_clear set: the cycle looks at them
        self._cam = {CAM_ENABLE: [0] * len(self.modules), CAM_POLARITY: [0] * len(self.modules)}

    def reset(self) -> None:
        """Forget master outputs and CAM settings (NMT reset node)."""
        n = len(self.modules)
        self.outputs = [_IDLE_OUTPUT] * n
        self.pending_clear = [CmpControl(0)] * n
        self._clear_armed = False
        self._cam = {CAM_ENABLE: [0] * n, CAM_POLARITY: [0] * n}
        for module in self.modules:
            module.set_process_output(_IDLE_OUTPUT)

    def _module(self, subindex: int) -> Xn1Ssi | None:
        if 1 <= subindex <= len(self.modules):
            return self.modules[subindex - 1]
        return None

    # -- SDO read ---------------------------------------------------------------------------
    def on_read(self, index: int, subindex: int, od: ODVariable) -> int | None:
        """LocalNode read callback: the live value, or None to fall back to stored data.

        :param index: the object's index
        :param subindex: the slot
        :param od: the dictionary entry (its data type)
        """
        module = self._module(subindex)
        if module is None or index not in SERVED:
            return None
        slot = subindex - 1
        if index in _STATUS_OBJECTS:
            return self._status_value(index, module.status)
        if index == PROCESS_INPUT:
            return int.from_bytes(module.process_input(), "little")
        if index == PROCESS_OUTPUT:
            return int.from_bytes(self.outputs[slot], "little")
        if index in REGISTER_OBJECTS:
            value = module.read_register(REGISTER_OBJECTS[index])
            if index == PRESET:  # added, not subtracted (000 object 6810hex)
                value = -value & 0xFFFFFFFF
            return to_int32(value) if index in SIGNED_OBJECTS else value
        if index == 0x5804:  # Table 27
            return int(module.diag)
        if index == 0x5806:  # Table 33: image byte 5, bits 6/7 masked
            return module.process_input()[5] & 0x3F
        if index == 0x6B00:  # Table 42
            return cam_state(module.ssi_pos, module.read_register(Reg.REG_CMP2),
                             module.read_register(Reg.REG_CMP1),
                             enabled=bool(self._cam[CAM_ENABLE][slot]),
                             polarity=self._cam[CAM_POLARITY][slot])
        if index in self._cam:
            return self._cam[index][slot]
        return None

    @staticmethod
    def _status_value(index: int, status: ProcessInput) -> int:
        """Objects decoded from process input bytes 6/7 (Tables 21, 24, 30; 6C00)."""
        if index == 0x5802:  # Table 21: STS_UP bit 7, STS_DN bit 6
            return int(status.cmp & (CmpStatus.STS_UP | CmpStatus.STS_DN))
        over = ModuleStatus.STS_OFLW in status.sts
        under = ModuleStatus.STS_UFLW in status.sts
        if index == 0x5803:  # Table 24
            return (bool(CmpStatus.FLAG_CMP1 in status.cmp) << 3
                    | bool(CmpStatus.FLAG_CMP2 in status.cmp) << 4
                    | over << 5 | under << 6)
        if index == 0x5805:  # Table 30: byte 0 = image byte 7, byte 1 = image byte 6
            return int(status.sts) | int(status.cmp) << 8
        return (AREA_OUT if over or under else 0) | (AREA_OVER if over else 0) | (
            AREA_UNDER if under else 0)

    def pdo_reader(self, index: int, subindex: int) -> Callable[[], bytes] | None:
        """A direct reader of the encoded value of a TPDO-mapped object, or None.

        Covers what the master maps on every SYNC (000 Table 15): 0x2000:s (the 8-byte process
        input image, :meth:`on_read` returns it as UNSIGNED64 little endian, i.e. the image
        bytes unchanged) and 0x6820:s (REG_SSI_POS as Integer32). The bytes equal what
        ``LocalNode.get_data`` would build through :meth:`on_read`, without the object
        lookups and int round trips; any other object takes that generic path (None).

        :param index: the mapped object's index
        :param subindex: the slot
        """
        module = self._module(subindex)
        if module is None:
            return None
        if index == PROCESS_INPUT:
            return module.process_input
        if index == POSITION:
            pack = POSITION_STRUCT.pack
            return lambda: pack(module.ssi_pos & 0xFFFFFFFF)
        return None

    def pdo_packer(self, entries: Sequence[tuple[int, int]]) -> Callable[[], bytes] | None:
        """One reader of a whole TPDO payload mapping only 0x6820 of several slots, or None.

        The encoder default PDOs 9-12 carry REG_SSI_POS of a slot pair (000 Table 15): one
        ``struct`` pack of both Integer32 values instead of one reader per entry and a join.
        Same bytes as the per-entry readers (``ssi_pos`` is kept within 0..0xFFFFFFFF).

        :param entries: the TPDO's mapped ``(index, subindex)`` pairs
        """
        if len(entries) < 2 or any(index != POSITION for index, _ in entries):
            return None
        found = [self._module(subindex) for _, subindex in entries]
        modules = [m for m in found if m is not None]
        if len(modules) != len(found):
            return None
        pack = struct.Struct("<" + "I" * len(modules)).pack
        if len(modules) == 2:
            first, second = modules
            return lambda: pack(first.ssi_pos, second.ssi_pos)
        return lambda: pack(*[m.ssi_pos for m in modules])

    # -- SDO write --------------------------------------------------------------------------
    def on_write(self, index: int, subindex: int, od: ODVariable, data: bytes) -> None:
        """LocalNode write callback: apply the write to the module or refuse it.

        :param index: the object's index
        :param subindex: the slot
        :param od: the dictionary entry (its data type)
        :param data: the written bytes
        :raises SdoAbortedError: a value the object or the module refuses (0x06090031 too high,
            0x06070010 not an integer, 0x06090030 refused by the module's rules)
        """
        module = self._module(subindex)
        if module is None or index not in SERVED:
            return
        slot = subindex - 1
        if index == PROCESS_OUTPUT:
            self.outputs[slot] = bytes(data)
            module.set_process_output(bytes(data))
        elif index in FLAG_RESET_OBJECTS:
            self.pending_clear[slot] = CmpControl.CLR_CMP1 | CmpControl.CLR_CMP2
            self._clear_armed = True
        elif index in self._cam:
            value = data[0]
            if value > 1:
                raise SdoAbortedError(SdoAbort.VALUE_TOO_HIGH)
            self._cam[index][slot] = value
        elif index in REGISTER_OBJECTS:
            raw = od.decode_raw(data)
            if not isinstance(raw, int):  # the register objects are integers (000 Table 16)
                raise SdoAbortedError(SdoAbort.LENGTH_MISMATCH)
            self._write_register(module, index, raw)

    @staticmethod
    def _write_register(module: Xn1Ssi, index: int, value: int) -> None:
        reg = REGISTER_OBJECTS[index]
        if index == PRESET:  # the preset is added: REG_OFFSET = -preset (000 object 6810hex)
            value = -value
        try:
            if reg is Reg.REG_PARA1:
                module.write_para1(value & 0xFFFFFFFF)
            else:
                module.write_register(reg, value & 0xFFFFFFFF)
        except ParameterError as err:
            logger.info("0x%04X slot %d: parameter set refused: %s", index, module.slot, err)
            raise SdoAbortedError(SdoAbort.INVALID_VALUE) from err
        except RegisterWriteError as err:
            logger.info("0x%04X slot %d: register write refused: %s", index, module.slot, err)
            raise SdoAbortedError(SdoAbort.INVALID_VALUE) from err

    # -- cycle ------------------------------------------------------------------------------
    def cycle(self, t: float) -> None:
        """Run one module cycle per slot, pulsing pending flag resets for that one cycle.

        :param t: the cycle's latch time (model time, s)
        """
        if not self._clear_armed:  # the common case: no flag reset pending
            for module in self.modules:
                module.cycle(t)
            return
        for slot, module in enumerate(self.modules):
            clear = self.pending_clear[slot]
            if clear:
                image = bytearray(self.outputs[slot])
                image[6] |= int(clear)
                module.set_process_output(bytes(image))
            module.cycle(t)
            if clear:
                self.pending_clear[slot] = CmpControl(0)
                module.set_process_output(self.outputs[slot])
        self._clear_armed = False  # after the loop: a slot a failing cycle skipped stays due
