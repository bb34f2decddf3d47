"""The XN-1SSI register handshake, run by the master over the process images (000 ch. 1-2).

Read (000 "Internal registers"): put the address in REG_RD_ADR (output byte 4); the value is
valid in REG_RD_DATA once the input echoes the address in REG_RD_ADR with REG_RD_ABORT = 0;
REG_RD_ABORT = 1 means the register cannot be read.

Write: wait until REG_WR_AKN = 0 with REG_WR = 0 (default state); send REG_WR_DATA,
REG_WR_ADR and REG_WR = 1; wait for REG_WR_AKN = 1 and take REG_WR_ACCEPT; send REG_WR = 0
and wait for REG_WR_AKN = 0 to return to the default state.

A read leaves REG_RD_ADR as it found it: the address the output image held before (the
node's idle read, REG_SSI_FRAME = 33, whose REG_RD_DATA the frame checks read every cycle)
is sent again after the read, and on success its echo awaited for one step, so the idle read
and what depends on it resume at once (000 "Internal registers": REG_RD_DATA shows the register
REG_RD_ADR names, in every cycle).

Each step has its own timeout (``step_timeout``) and the whole transaction a deadline, so a
call is bounded whatever the bus does. Bytes 6/7 of the output (comparator control, STOP)
belong to ``set_control`` and are never touched here.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Protocol

from ssi_bridge.exceptions import (
    GatewayUnavailable, HandshakeTimeout, ParameterError, RegisterReadError, RegisterWriteError,
)
from ssi_bridge.protocol.images import ADDRESS_MASK, ProcessInput, WriteRequest
from ssi_bridge.protocol.registers import REGISTER_COUNT, VALUE_MAX, Reg, describe_refusal
from ssi_bridge.protocol.registers import validate_para1

logger = logging.getLogger(__name__)

#: output image byte offsets (000 "Process output")
OUT_RD_ADR, OUT_WR_ADR = 4, 5
#: steps of one write transaction (REG_WR_AKN = 0 first, then set, then release)
WRITE_STEPS = 3


class ImagePort(Protocol):
    """How the handshake reaches one slot's process images (PDO or SDO transport)."""

    def edit_output(self, slot: int, edit: Callable[[bytearray], None]) -> None:
        """Apply ``edit`` to bytes 0-5 of the slot's output image and send it."""

    def next_input(self, slot: int, timeout: float) -> ProcessInput | None:
        """Return an input image produced after the last ``edit_output`` (None on timeout).

        :param slot: the module's slot (1-8)
        :param timeout: longest wait (s)
        """

    def alive(self) -> bool:
        """Whether the gateway's heartbeat is current."""


def check_address(addr: int, write: bool) -> None:
    """Refuse an address the 6-bit REG_xx_ADR field cannot carry, before any bus traffic.

    :param addr: the register address
    :param write: for a write (RegisterWriteError) or a read (RegisterReadError)
    :raises RegisterReadError: a read of an address outside 0-63
    :raises RegisterWriteError: a write to an address outside 0-63
    """
    if not 0 <= addr < REGISTER_COUNT:
        error = RegisterWriteError if write else RegisterReadError
        raise error(addr, f"out of range 0..{REGISTER_COUNT - 1}")


class Handshake:
    """One slot's handshake engine over an :class:`ImagePort` (the caller holds the slot lock).

    :param port: the slot's process images (the master's PDO or SDO transport)
    :param step_timeout: bound of one handshake step (s)
    :param total_timeout: bound of one whole transaction (s)
    """

    def __init__(self, port: ImagePort, step_timeout: float, total_timeout: float) -> None:
        self.port = port
        self.step_timeout = step_timeout
        self.total_timeout = total_timeout

    def _await(self, slot: int, addr: int, op: str, step: str, deadline: float,
               done: Callable[[ProcessInput], bool], resend: Callable[[], None]) -> ProcessInput:
        """Wait for an input image satisfying ``done``; re-send the request on a fresh image
        that does not (the output frame may have been lost)."""
        step_end = min(time.monotonic() + self.step_timeout, deadline)
        last: ProcessInput | None = None
        while True:
            left = step_end - time.monotonic()
            if left <= 0:
                break
            image = self.port.next_input(slot, left)
            if image is None:
                continue
            last = image
            if done(image):
                return image
            resend()
        where = f"slot {slot}: register 0x{addr:02X} ({addr}) {op}, step '{step}'"
        seen = "no input image at all" if last is None else f"last input {last.encode().hex()}"
        if not self.port.alive():
            raise GatewayUnavailable(f"{where}: gateway silent (no heartbeat); {seen}")
        raise HandshakeTimeout(f"{where}: no answer within {self.step_timeout:.3f} s "
                               f"(total budget {self.total_timeout:.3f} s); {seen}")

    def read(self, slot: int, addr: int) -> int:
        """Read register ``addr`` of ``slot`` through the process images; REG_RD_ADR is then
        set back to the address it held before (see the module docstring).

        :returns: the register's value (REG_RD_DATA)
        :raises RegisterReadError: the address is out of range or the module aborted the read
        :raises HandshakeTimeout: a step got no answer in time
        :raises GatewayUnavailable: the gateway's heartbeat is not current
        """
        check_address(addr, write=False)
        deadline = time.monotonic() + self.total_timeout
        before: list[int] = []  # REG_RD_ADR of the output image before this read

        def request(out: bytearray) -> None:
            if not before:
                before.append(out[OUT_RD_ADR])
            out[OUT_RD_ADR] = addr & ADDRESS_MASK

        def send() -> None:
            self.port.edit_output(slot, request)

        send()
        try:
            image = self._await(slot, addr, "read", "REG_RD_ADR echo", deadline,
                                lambda i: i.reg_rd_adr == addr, send)
        except Exception:
            self._restore_read_address(slot, before, wait=False)
            raise
        self._restore_read_address(slot, before, wait=True)
        if image.reg_rd_abort:
            reason = describe_refusal(addr, write=False) or "module answered REG_RD_ABORT = 1"
            raise RegisterReadError(addr, reason,
                                    f"slot {slot}: register 0x{addr:02X} ({addr}) cannot be "
                                    f"read: {reason} (REG_RD_ABORT = 1)")
        return image.reg_rd_data

    def _restore_read_address(self, slot: int, before: list[int], wait: bool) -> None:
        """Send REG_RD_ADR = ``before[0]`` again; with ``wait``, await its echo for one step
        (re-sent on an image without it). Never raises: the read itself is done."""
        if not before:
            return
        idle = before[0]

        def restore(out: bytearray) -> None:
            out[OUT_RD_ADR] = idle

        def send() -> None:
            self.port.edit_output(slot, restore)

        send()
        if not wait:
            return
        address = idle & ADDRESS_MASK
        try:
            self._await(slot, address, "read", "REG_RD_ADR back to the idle read",
                        time.monotonic() + self.step_timeout,
                        lambda i: i.reg_rd_adr == address, send)
        except (HandshakeTimeout, GatewayUnavailable) as err:
            logger.warning("slot %d: REG_RD_ADR set back to %d, not echoed yet: %s", slot,
                           idle, err)

    def write(self, slot: int, addr: int, value: int) -> None:
        """Write ``value`` to register ``addr`` of ``slot`` (000 write handshake).

        :raises RegisterWriteError: the address is out of range or the module refused the value
            (:class:`ParameterError` for a REG_PARA1 it rejects, with the reason)
        :raises HandshakeTimeout: a step got no answer in time
        :raises GatewayUnavailable: the gateway's heartbeat is not current
        """
        check_address(addr, write=True)
        if not 0 <= value <= VALUE_MAX:
            raise RegisterWriteError(addr, f"value {value} out of range 0..0x{VALUE_MAX:X}")
        deadline = time.monotonic() + self.total_timeout

        def release(out: bytearray) -> None:
            out[OUT_WR_ADR] &= ~WriteRequest.REG_WR & 0xFF

        def request(out: bytearray) -> None:
            out[0:4] = value.to_bytes(4, "big")
            out[OUT_WR_ADR] = (addr & ADDRESS_MASK) | WriteRequest.REG_WR

        def send_release() -> None:
            self.port.edit_output(slot, release)

        def send_request() -> None:
            self.port.edit_output(slot, request)

        try:
            send_release()
            self._await(slot, addr, "write", "REG_WR_AKN = 0 before the write", deadline,
                        lambda i: not i.reg_wr_akn, send_release)
            send_request()
            acked = self._await(slot, addr, "write", "REG_WR_AKN = 1", deadline,
                                lambda i: i.reg_wr_akn, send_request)
            send_release()
            self._await(slot, addr, "write", "REG_WR_AKN = 0 after REG_WR = 0", deadline,
                        lambda i: not i.reg_wr_akn, send_release)
        except Exception:
            send_release()  # never leave REG_WR = 1 behind
            raise
        if not acked.reg_wr_accept:
            raise self._refusal(slot, addr, value)

    @staticmethod
    def _refusal(slot: int, addr: int, value: int) -> RegisterWriteError:
        where = f"slot {slot}: register 0x{addr:02X} ({addr})"
        if addr == Reg.REG_PARA1:
            reason = validate_para1(value) or "parameter set refused"
            return ParameterError(addr, reason, f"{where}: REG_PARA1 0x{value:08X} refused "
                                  f"(ERR_PARA): {reason}")
        reason = describe_refusal(addr, write=True) or "value refused by the module"
        return RegisterWriteError(addr, reason, f"{where}: write of 0x{value:08X} refused "
                                  f"(REG_WR_ACCEPT = 0): {reason}")
