"""Emergencies of the station: EMCY 0x7000 per diagnostics edge, 0x1001 and 0x1003.

000 chapter 4 "Additional emergencies": error code 0x7000 "Additional modules", byte 3 =
module number, byte 4 = channel number (always 1), byte 5 = the diagnostics bit (0x01 SSI
diag, 0x02 SSI error, 0x04 overflow, 0x08 underflow, 0x10 parameter error). One EMCY per
rising edge; when every module's diagnostics byte is clear again the station sends the
error-reset EMCY (code 0x0000) and clears the error register 0x1001 (CiA 301 7.2.7).
0x1003 holds the newest ``ERROR_HISTORY`` errors, newest at sub 1, each as
``additional info << 16 | error code`` with additional info = module number << 8 | bit.
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Callable, Sequence

from canopen.sdo import SdoAbortedError

from ssi_bridge.protocol.aborts import SdoAbort
from ssi_bridge.protocol.dictionary import ERROR_HISTORY
from ssi_bridge.protocol.diagnostics import EMCY_ADDITIONAL_MODULES, EMCY_CHANNEL, Diag, DiagTracker

logger = logging.getLogger(__name__)

#: manufacturer-specific part of the 0x7000 EMCY: module no., channel, diag bit, 2 x 0
EMCY_DATA = struct.Struct("<BBBxx")
#: CiA 301 error register 0x1001 bit 0: generic error (set whenever any error is present)
ERR_REG_GENERIC = 0x01
#: bit 7: manufacturer specific (here: an XN-1SSI module reports a diagnostic)
ERR_REG_MANUFACTURER = 0x80
ERROR_REGISTER, ERROR_FIELD = 0x1001, 0x1003


class Emergencies:
    """Track module diagnostics and produce EMCYs through ``send(code, register, data)``."""

    def __init__(self, slots: int, send: Callable[[int, int, bytes], None]) -> None:
        self._send = send
        self._trackers = [DiagTracker(slot) for slot in range(1, slots + 1)]
        self.history: list[int] = []
        self.error_register = 0

    def reset(self) -> None:
        """Forget the history and all active diagnostics (NMT reset)."""
        self._trackers = [DiagTracker(t.slot) for t in self._trackers]
        self.history = []
        self.error_register = 0

    def update(self, diags: Sequence[Diag], *, may_send: bool) -> None:
        """Compare each slot's diagnostics byte with the last one and emit EMCYs."""
        was_active = self.error_register != 0
        for tracker, diag in zip(self._trackers, diags):
            if diag == tracker.current:
                continue  # no edge: the common case on every SYNC
            for edge in tracker.update(diag):
                if not edge.rising:
                    continue
                self.error_register = ERR_REG_GENERIC | ERR_REG_MANUFACTURER
                info = edge.slot << 8 | edge.emcy_value
                self.history = ([info << 16 | EMCY_ADDITIONAL_MODULES] + self.history)[
                    :ERROR_HISTORY]
                # DEBUG: the master side logs the EMCYs it receives, summarised
                logger.debug("slot %d: %s -> EMCY 0x%04X", edge.slot, edge.text,
                             EMCY_ADDITIONAL_MODULES)
                if may_send:
                    self._send(EMCY_ADDITIONAL_MODULES, self.error_register,
                               EMCY_DATA.pack(edge.slot, EMCY_CHANNEL, edge.emcy_value))
        if was_active and all(not t.current for t in self._trackers):
            self.error_register = 0
            logger.debug("all module diagnostics clear -> error reset EMCY")
            if may_send:
                self._send(0x0000, 0, bytes(5))

    def on_read(self, index: int, subindex: int, od: object) -> int | None:
        """LocalNode read callback for 0x1001 and 0x1003."""
        if index == ERROR_REGISTER:
            return self.error_register
        if index == ERROR_FIELD:
            if subindex == 0:
                return len(self.history)
            return self.history[subindex - 1] if subindex <= len(self.history) else 0
        return None

    def on_write(self, index: int, subindex: int, od: object, data: bytes) -> None:
        """0x1003 sub 0: writing 0 clears the history, anything else is refused (CiA 301)."""
        if index == ERROR_FIELD and subindex == 0:
            if data[0] != 0:
                raise SdoAbortedError(SdoAbort.INVALID_VALUE)
            self.history = []
