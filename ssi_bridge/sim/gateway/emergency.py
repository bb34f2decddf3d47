"""Emergencies of the station: EMCY 0x7000 per diagnostics edge, 0x1001 and 0x1003.

000 chapter 4 "Additional emergencies": error code 0x7000 "Additional modules", byte 3 =
module number, byte 4 = channel number (always 1), byte 5 = the diagnostics bit (0x01 SSI
diag, 0x02 SSI error, 0x04 overflow, 0x08 underflow, 0x10 parameter error). One EMCY per
rising edge; when every module's diagnostics byte is clear again the station sends the
error-reset EMCY (code 0x0000) and clears the error register 0x1001 (CiA 301 7.2.7).
0x1003 holds the newest ``ERROR_HISTORY`` errors, newest at sub 1, each as
``additional info << 16 | error code`` with additional info = module number << 8 | bit.

A CAN overrun of the gateway's controller (its receive FIFO lost frames, ``controller.py``)
is CiA 301's EMCY 0x8110 "CAN overrun (objects lost)", sent once per overrun episode with
error register bit 4 (communication error) set, bytes 3-6 = frames lost so far (UNSIGNED32);
the bit clears with the next SYNC the gateway handles, and when no other error remains the
error-reset EMCY follows (CiA 301 7.2.7).
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Callable, Sequence

from canopen import SdoAbortedError

from ssi_bridge.protocol.aborts import SdoAbort
from ssi_bridge.protocol.dictionary import ERROR_HISTORY
from ssi_bridge.protocol.diagnostics import EMCY_ADDITIONAL_MODULES, EMCY_CHANNEL, Diag, DiagTracker

logger = logging.getLogger(__name__)

#: manufacturer-specific part of the 0x7000 EMCY: module no., channel, diag bit, 2 x 0
EMCY_DATA = struct.Struct("<BBBxx")
#: CiA 301 error register 0x1001 bit 0: generic error (set whenever any error is present)
ERR_REG_GENERIC = 0x01
#: bit 4: communication error (overrun, error state)
ERR_REG_COMMUNICATION = 0x10
#: bit 7: manufacturer specific (here: an XN-1SSI module reports a diagnostic)
ERR_REG_MANUFACTURER = 0x80
#: CiA 301 emergency error code: CAN overrun (objects lost)
EMCY_CAN_OVERRUN = 0x8110
#: manufacturer-specific part of the 0x8110 EMCY: frames lost so far, 1 x 0
OVERRUN_DATA = struct.Struct("<Ix")
ERROR_REGISTER, ERROR_FIELD = 0x1001, 0x1003


class Emergencies:
    """Track module diagnostics and produce EMCYs through ``send(code, register, data)``.

    :param slots: the station's modules (1-8)
    :param send: puts one EMCY on the bus
    """

    def __init__(self, slots: int, send: Callable[[int, int, bytes], None]) -> None:
        self._send = send
        self._trackers = [DiagTracker(slot) for slot in range(1, slots + 1)]
        self.history: list[int] = []
        self.error_register = 0
        #: a module reports a diagnostics bit
        self._module_error = False
        #: a CAN overrun episode is in progress (error register bit 4)
        self.overrun_active = False

    def reset(self) -> None:
        """Forget the history and all active diagnostics (NMT reset)."""
        self._trackers = [DiagTracker(t.slot) for t in self._trackers]
        self.history = []
        self.error_register = 0
        self._module_error = self.overrun_active = False

    def _register(self) -> int:
        """0x1001 from the errors in force (CiA 301: bit 0 whenever any is)."""
        register = ERR_REG_GENERIC | ERR_REG_MANUFACTURER if self._module_error else 0
        if self.overrun_active:
            register |= ERR_REG_GENERIC | ERR_REG_COMMUNICATION
        return register

    def _push(self, entry: int) -> None:
        self.history = ([entry] + self.history)[:ERROR_HISTORY]

    def overrun(self, lost: int, *, may_send: bool) -> None:
        """An overrun episode began (the controller lost a frame; ``lost`` frames so far):
        EMCY 0x8110 once, error register bit 4 until :meth:`overrun_over`, a 0x1003 entry.

        :param may_send: the NMT state allows EMCYs (not in STOPPED)
        """
        self.overrun_active = True
        self.error_register = self._register()
        self._push(EMCY_CAN_OVERRUN)
        logger.debug("CAN overrun (%d frames lost so far) -> EMCY 0x%04X", lost, EMCY_CAN_OVERRUN)
        if may_send:
            self._send(EMCY_CAN_OVERRUN, self.error_register,
                       OVERRUN_DATA.pack(min(lost, 0xFFFF_FFFF)))

    def overrun_over(self, *, may_send: bool) -> None:
        """The overrun episode is over: bit 4 clears; the error-reset EMCY when no error is
        left.

        :param may_send: the NMT state allows EMCYs (not in STOPPED)
        """
        if not self.overrun_active:
            return
        self.overrun_active = False
        self.error_register = self._register()
        if not self.error_register and may_send:
            self._send(0x0000, 0, bytes(5))

    def update(self, diags: Sequence[Diag], *, may_send: bool) -> None:
        """Compare each slot's diagnostics byte with the last one and emit EMCYs.

        :param diags: each slot's diagnostics byte after the cycle
        :param may_send: the NMT state allows EMCYs (not in STOPPED)
        """
        was_active = self._module_error
        for tracker, diag in zip(self._trackers, diags):
            if diag == tracker.current:
                continue  # no edge: the common case on every SYNC
            for edge in tracker.update(diag):
                if not edge.rising:
                    continue
                self._module_error = True
                self.error_register = self._register()
                info = edge.slot << 8 | edge.emcy_value
                self._push(info << 16 | EMCY_ADDITIONAL_MODULES)
                # DEBUG: the master side logs the EMCYs it receives, summarised
                logger.debug("slot %d: %s -> EMCY 0x%04X", edge.slot, edge.text,
                             EMCY_ADDITIONAL_MODULES)
                if may_send:
                    self._send(EMCY_ADDITIONAL_MODULES, self.error_register,
                               EMCY_DATA.pack(edge.slot, EMCY_CHANNEL, edge.emcy_value))
        if was_active and all(not t.current for t in self._trackers):
            self._module_error = False
            self.error_register = self._register()
            if not self.error_register:
                logger.debug("all module diagnostics clear -> error reset EMCY")
                if may_send:
                    self._send(0x0000, 0, bytes(5))

    def on_read(self, index: int, subindex: int, od: object) -> int | None:
        """LocalNode read callback for 0x1001 and 0x1003.

        :param index: the object's index
        :param subindex: its subindex
        :param od: the dictionary entry (unused)
        :returns: the value, or None for another object (stored data)
        """
        if index == ERROR_REGISTER:
            return self.error_register
        if index == ERROR_FIELD:
            if subindex == 0:
                return len(self.history)
            return self.history[subindex - 1] if subindex <= len(self.history) else 0
        return None

    def on_write(self, index: int, subindex: int, od: object, data: bytes) -> None:
        """0x1003 sub 0: writing 0 clears the history, anything else is refused (CiA 301).

        :param index: the object's index
        :param subindex: its subindex
        :param od: the dictionary entry (unused)
        :param data: the written bytes
        :raises SdoAbortedError: 0x1003:0 written with anything but 0 (0x06090030)
        """
        if index == ERROR_FIELD and subindex == 0:
            if data[0] != 0:
                raise SdoAbortedError(SdoAbort.INVALID_VALUE)
            self.history = []
