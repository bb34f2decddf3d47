"""The CAN error frames the master's interface reports, counted per class and understood.

SocketCAN (and python-can interfaces that do the same) hands the application an error frame
for what its controller saw: bus-off, error passive / warning, a lost arbitration, a missing
ACK, a protocol violation (``protocol/can_errors.py`` decodes them). :class:`ErrorFrameWatch`
counts each class, keeps the controller state the frames report, and logs each class at most
once per second. For the bus diagnostics:

* :meth:`ErrorFrameWatch.problem`: bus-off (an ERROR) until the controller reports a restart
  or error active again, the interface is reopened, or :data:`RECOVERY_FRAMES` frames were
  received since (a bus-off controller receives nothing; a frame or two may still have been
  on their way when it was reported);
* :meth:`ErrorFrameWatch.warning`: error passive or error warning (a WARN) until it reports
  error active (CAN_ERR_CRTL_ACTIVE, CAN_ERR_RESTARTED, or counters below 96);
* :meth:`ErrorFrameWatch.figures`: a count per class (``error_frames_<class>``), the
  controller state and its last error counters, as key-values.
"""

from __future__ import annotations

import logging
import threading
from collections import Counter

from ssi_bridge.base.rate_log import RateLimitedLog
from ssi_bridge.protocol.can_errors import (
    BUS_OFF, CLASS_NAMES, ERROR_ACTIVE, ERROR_PASSIVE, ERROR_WARNING, decode_error_frame,
)

logger = logging.getLogger(__name__)

#: key prefix of the per-class counts in the bus diagnostics
PREFIX = "error_frames_"
#: frames received after a bus-off report that show the controller works again
RECOVERY_FRAMES = 20


class ErrorFrameWatch:
    """Error frames of one bus (receive thread in, diagnostics out; thread-safe)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._log = RateLimitedLog(logger)
        #: error frames per class name (``protocol/can_errors.CLASS_NAMES``)
        self.counts: Counter[str] = Counter()
        #: the controller state the frames reported last, and the frame that said so
        self.state = ERROR_ACTIVE
        self.state_text = ""
        #: the last TX / RX error counters reported (CAN_ERR_CNT), None before
        self.counters: tuple[int, int] | None = None
        #: frames received since the last bus-off report
        self._heard = 0

    @property
    def bus_off(self) -> bool:
        """True while the last state reported is bus-off (read per frame: no lock)."""
        return self.state == BUS_OFF

    def observe(self, mask: int, data: bytes | bytearray) -> None:
        """One error frame: its class ``mask`` (the identifier) and data bytes."""
        frame = decode_error_frame(mask, data)
        with self._lock:
            self.counts.update(frame.classes)
            if frame.state is not None:
                self.state, self.state_text = frame.state, frame.text()
                self._heard = 0
            if frame.tx_errors is not None and frame.rx_errors is not None:
                self.counters = (frame.tx_errors, frame.rx_errors)
            counts = {name: self.counts[name] for name in frame.classes}
        for name, n in counts.items():
            level = logging.ERROR if name == "bus_off" else logging.WARNING
            self._log.log(level, name, "CAN error frame (%s, 0x%03X): %s (%d of this class so "
                          "far)", name, mask, frame.text(), n)

    def heard(self, can_id: int) -> None:
        """A frame was received while bus-off is reported (receive thread).

        :param can_id: the received frame's identifier
        """
        self._heard += 1
        if self._heard >= RECOVERY_FRAMES:
            self.recovered(f"{self._heard} frames received since, the last 0x{can_id:03X}")

    def recovered(self, why: str) -> None:
        """The controller works again after bus-off (``why``: frames received, reopened)."""
        with self._lock:
            if self.state != BUS_OFF:
                return
            self.state, self.state_text = ERROR_ACTIVE, why
        logger.warning("CAN controller no longer bus-off: %s", why)

    def problem(self) -> str:
        """Bus-off in words for an ERROR of the bus diagnostics ("" otherwise)."""
        with self._lock:
            if self.state != BUS_OFF:
                return ""
            return (f"CAN controller bus-off ({self.state_text}): it sends and receives "
                    "nothing until restarted (socketcan: restart-ms, or ip link set down/up)")

    def warning(self) -> str:
        """Error passive / warning in words for a WARN of the bus diagnostics ("")."""
        with self._lock:
            if self.state not in (ERROR_PASSIVE, ERROR_WARNING):
                return ""
            return f"CAN controller {self.state} ({self.state_text})"

    def figures(self) -> dict[str, str | int]:
        """A count per class, the controller state and its error counters (key-values)."""
        with self._lock:
            out: dict[str, str | int] = {f"{PREFIX}{name}": self.counts[name]
                                         for name in CLASS_NAMES.values()}
            out["can_controller_state"] = self.state
            if self.counters is not None:
                out["can_tx_error_counter"], out["can_rx_error_counter"] = self.counters
        return out


def error_frame_keys() -> tuple[str, ...]:
    """The diagnostics keys of the per-class counts (their growth is a WARN)."""
    return tuple(f"{PREFIX}{name}" for name in CLASS_NAMES.values())


__all__ = ["ErrorFrameWatch", "PREFIX", "RECOVERY_FRAMES", "error_frame_keys"]
