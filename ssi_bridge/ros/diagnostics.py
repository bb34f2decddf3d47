"""Diagnostic statuses of the bridge: one per joint channel and one for the bus/gateway.

Level mapping (docs/node.md has the table):

=================================================  =========
condition                                           level
=================================================  =========
no fresh sample for ``stale_cycles`` cycles          STALE
ERR_PARA (invalid REG_PARA1) or ERR_SSI (wire)       ERROR
STS_OFLW / STS_UFLW (limits), SSI_DIAG, STS_STOP     WARN
otherwise                                           OK
gateway silent (no heartbeat) / not connected       ERROR (bus)
achieved rate < 90 % of publish_rate, CAN errors    WARN (bus)
=================================================  =========
"""

from __future__ import annotations

from dataclasses import dataclass

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

from ssi_bridge.module.images import ModuleStatus, ProcessInput

OK, WARN, ERROR, STALE = (DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR,
                          DiagnosticStatus.STALE)


@dataclass
class ChannelCounters:
    """Per-joint counters the node keeps between diagnostics messages."""

    samples: int = 0
    stale_cycles: int = 0
    consecutive_stale: int = 0
    error_cycles: int = 0
    handshake_failures: int = 0
    #: the latest 8-byte process input image (decoded only when a status is built)
    last_image: bytes | None = None
    last_position: int = 0

    @property
    def last_input(self) -> ProcessInput | None:
        """The latest process input image, decoded."""
        return ProcessInput.decode(self.last_image) if self.last_image is not None else None

    @property
    def last_sts(self) -> int | None:
        """Byte 7 of the latest image (STS_STOP, ERR_PARA, ... SSI_DIAG), None before one."""
        return self.last_image[7] if self.last_image is not None else None


_WARN_BITS = (
    (int(ModuleStatus.STS_OFLW), "STS_OFLW: above REG_UPPER_LIMIT"),
    (int(ModuleStatus.STS_UFLW), "STS_UFLW: below REG_LOWER_LIMIT"),
    (int(ModuleStatus.SSI_DIAG), "SSI_DIAG: an enabled encoder status bit is set"),
    (int(ModuleStatus.STS_STOP), "STS_STOP: acquisition stopped by STOP"),
)
_WARN_MASK = sum(bit for bit, _ in _WARN_BITS)
_ERR_PARA, _ERR_SSI = int(ModuleStatus.ERR_PARA), int(ModuleStatus.ERR_SSI)


def channel_level(sts: int | None, consecutive_stale: int, stale_limit: int
                  ) -> tuple[int, str]:
    """Level and one-line message of a joint channel from byte 7 of its process input.

    Plain int tests: this runs every cycle for every joint.
    """
    if sts is None:
        return STALE, "no sample received yet"
    if consecutive_stale >= stale_limit:
        return STALE, f"no fresh sample for {consecutive_stale} cycles"
    if sts & _ERR_PARA:
        return ERROR, "ERR_PARA: the module rejected REG_PARA1, encoder not read"
    if sts & _ERR_SSI:
        return ERROR, "ERR_SSI: SSI encoder signal faulty (wire break or no data)"
    if sts & _WARN_MASK:
        return WARN, "; ".join(text for bit, text in _WARN_BITS if sts & bit)
    return OK, "reading"


def channel_status(joint: str, hardware_id: str, counters: ChannelCounters, stale_limit: int,
                   position: float) -> DiagnosticStatus:
    """The DiagnosticStatus ``ssi_bridge: <joint>`` with every status bit as a key/value."""
    inp = counters.last_input
    level, message = channel_level(counters.last_sts, counters.consecutive_stale, stale_limit)
    values = {
        "position": f"{position:.6f}",
        "REG_SSI_POS": str(counters.last_position),
        "samples": str(counters.samples),
        "stale_cycles": str(counters.stale_cycles),
        "error_cycles": str(counters.error_cycles),
        "handshake_failures": str(counters.handshake_failures),
    }
    if inp is not None:
        values.update({name: str(value) for name, value in inp.bits().items()})
    return DiagnosticStatus(
        level=level, name=f"ssi_bridge: {joint}", message=message, hardware_id=hardware_id,
        values=[KeyValue(key=k, value=v) for k, v in values.items()])


def bus_status(name: str, hardware_id: str, *, alive: bool, connected: bool,
               achieved_rate: float, publish_rate: float, counters: dict[str, int],
               extra_error: str = "") -> DiagnosticStatus:
    """The bus/gateway status: liveness, achieved vs configured rate and CAN counters."""
    if not connected:
        level, message = ERROR, "not connected to the gateway"
    elif not alive:
        level, message = ERROR, "gateway silent: no heartbeat / no TPDOs"
        if extra_error:  # e.g. why: the simulated station's process ended
            message += f"; {extra_error}"
    elif extra_error:
        level, message = ERROR, extra_error
    elif achieved_rate < 0.9 * publish_rate:
        level, message = WARN, f"cycle rate {achieved_rate:.1f} Hz below {publish_rate:.1f} Hz"
    else:
        level, message = OK, f"cycling at {achieved_rate:.1f} Hz"
    values = {"achieved_rate_hz": f"{achieved_rate:.2f}", "publish_rate_hz": f"{publish_rate:.2f}",
              "gateway_alive": str(alive)}
    values.update({k: str(v) for k, v in counters.items()})
    return DiagnosticStatus(level=level, name=name, message=message, hardware_id=hardware_id,
                            values=[KeyValue(key=k, value=v) for k, v in values.items()])


def station_status(name: str, hardware_id: str, *, alive: bool, nmt_state: str,
                   emcy: list[str], counters: dict[str, int]) -> DiagnosticStatus:
    """One station (XN-GW-CANOPEN) of several on the bus: heartbeat, NMT state, EMCY history.

    ERROR while its heartbeat is missing (the station's joints go stale with it), WARN while
    an EMCY is active (error register not zero), else OK.
    """
    if not alive:
        level, message = ERROR, "gateway silent: no heartbeat"
    elif emcy and not emcy[-1].startswith("0x0000"):
        level, message = WARN, f"EMCY {emcy[-1]}"
    else:
        level, message = OK, f"heartbeat {nmt_state}"
    values = {"gateway_alive": str(alive), "nmt_state": nmt_state,
              "emcy_count": str(len(emcy)), "emcy_history": "; ".join(emcy[-8:])}
    values.update({k: str(v) for k, v in counters.items()})
    return DiagnosticStatus(level=level, name=name, message=message, hardware_id=hardware_id,
                            values=[KeyValue(key=k, value=v) for k, v in values.items()])


__all__ = ["ChannelCounters", "bus_status", "channel_level", "channel_status", "station_status"]
