"""EMCY edges as log lines a person can read: at most one line per second per slot and code.

A module whose diagnostics flap (a REG_PARA1 that does not fit the encoder, a loose cable)
makes the gateway send an EMCY 0x7000 per rising edge and the error-reset EMCY 0x0000 each
time everything clears (000 chapter 4 "Additional emergencies") — over a hundred frames a
second at 1 kHz. Each one is counted (``counters.emergencies``, canopen's EMCY log); the log
gets the first edge of a (slot, code, diagnostics bit) at once and then at most one line per
second for it, carrying how many edges it stands for.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass

#: 000 "Additional emergencies": the module-diagnostics EMCY and its diagnostics bits
EMCY_ADDITIONAL_MODULES = 0x7000
DIAG_BITS = {0x01: "SSI diag", 0x02: "SSI error", 0x04: "overflow", 0x08: "underflow",
             0x10: "parameter error"}
#: seconds between two lines of the same slot and code
PERIOD_S = 1.0


@dataclass
class _Key:
    """How often one (slot, code, bit) was seen since its last log line."""

    last: float
    hidden: int = 0


def describe(code: int, data: bytes) -> tuple[tuple[int, int, int], str]:
    """The summary key (slot, code, bit) and a readable text of one EMCY.

    :param code: the emergency error code
    :param data: its 5 manufacturer-specific bytes (byte 0: the slot, 1: the diagnostics bits)
    """
    if code == EMCY_ADDITIONAL_MODULES and len(data) >= 3:
        slot, bit = data[0], data[2]
        what = DIAG_BITS.get(bit, f"diagnostics bit 0x{bit:02X}")
        return (slot, code, bit), f"EMCY 0x{code:04X} slot {slot}: {what}"
    if code == 0:
        return (0, 0, 0), "EMCY 0x0000 error reset: every module's diagnostics clear"
    return (0, code, 0), f"EMCY 0x{code:04X} data {data.hex()}"


class EmcySummary:
    """Log EMCYs at INFO, each (slot, code, bit) at most once per ``period`` seconds.

    :param logger: where the lines go
    :param prefix: put before each line (e.g. the gateway's node id)
    :param period: at most one line per (slot, code, bit) per this many seconds
    :param clock: the monotonic clock the period is measured on
    """

    def __init__(self, logger: logging.Logger, prefix: str = "", period: float = PERIOD_S,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self._logger = logger
        self._prefix = prefix
        self._period = period
        self._clock = clock
        self._keys: dict[tuple[int, int, int], _Key] = {}

    def on_emcy(self, code: int, data: bytes) -> bool:
        """Count one EMCY; True if it was logged, False if it waits for the next line.

        :param code: the emergency error code
        :param data: its manufacturer-specific bytes
        """
        key, text = describe(code, data)
        now = self._clock()
        seen = self._keys.get(key)
        if seen is not None and now - seen.last < self._period:
            seen.hidden += 1
            return False
        more = ""
        if seen is not None and seen.hidden:
            more = f" (and {seen.hidden} more in the last {now - seen.last:.1f} s)"
        self._keys[key] = _Key(now)
        self._logger.info("%s%s%s", self._prefix, text, more)
        return True
