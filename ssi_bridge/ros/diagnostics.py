"""Diagnostic statuses of the bridge: one per joint channel and one for the bus/gateway.

The levels and messages of a joint come from its core (``core/health.py`` has the level
table and the debounce, docs/node.md the same for a reader); this module puts them, every
status bit and the counters into ``diagnostic_msgs``. The bus status adds: gateway silent
(no heartbeat) or not connected ERROR; achieved rate below 90 % of publish_rate or CAN errors
WARN.
"""

from __future__ import annotations

from collections.abc import Mapping

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

from ssi_bridge.core.health import (
    ERROR, OK, WARN, ChannelCounters, ChannelHealth, Level, channel_level,
)
from ssi_bridge.protocol.frame_check import FrameVerdict


def status_name(node_fqn: str, item: str) -> str:
    """``<node FQN>: <item>`` (e.g. ``/station_a/ssi_bridge: shoulder``): unique per bridge."""
    return f"{node_fqn}: {item}"


def channel_status(name: str, hardware_id: str, counters: ChannelCounters,
                   health: ChannelHealth, position: float,
                   extra: dict[str, str] | None = None) -> DiagnosticStatus:
    """A joint's DiagnosticStatus (``<node FQN>: <joint>``), every status bit a key/value."""
    inp = counters.last_input
    values = {
        "position": f"{position:.6f}",
        "REG_SSI_POS": str(counters.last_position),
        "samples": str(counters.samples),
        "stale_cycles": str(counters.stale_cycles),
        "stale_ratio": f"{health.stale_ratio:.3f}",
        "error_cycles": str(counters.error_cycles),
        "handshake_failures": str(counters.handshake_failures),
        "implausible_jumps": str(counters.implausible),
        "samples_set_aside": str(counters.set_aside),
        "left_out_because": counters.last_reason,
    }
    values.update(extra or {})
    if inp is not None:
        values.update({name: str(value) for name, value in inp.bits().items()})
    level, message = health.level, health.message
    frame = counters.frame
    values["frame_errors"] = str(counters.frame_errors)
    if frame is not None:
        values.update({"POWER_FAILURE": str(frame.power_failure),
                       "ENCODER_ERROR": str(frame.encoder_error),
                       "PARITY_ERROR": str(frame.parity_error),
                       "FILLER_ERROR": str(frame.filler_error),
                       "CHECKSUM_ERROR": str(frame.checksum_error)})
        level, message = _with_frame_findings(level, message, frame)
    return DiagnosticStatus(
        level=level, name=name, message=message, hardware_id=hardware_id,
        values=[KeyValue(key=k, value=v) for k, v in values.items()])


def _with_frame_findings(level: Level, message: str, frame: FrameVerdict
                         ) -> tuple[Level, str]:
    """Raise level/message by what the frame check saw in the raw SSI frame.

    The frame check sees a bit at once while the module's own status (SSI_DIAG ...) passes the
    debounce first, so both findings are kept in the message rather than one hiding the other.
    """
    findings = [text for flag, text in (
        (frame.parity_error, "parity error (001 5.5.7)"),
        (frame.filler_error, "bit that must be 0 read as 1 (004 3)"),
        (frame.checksum_error, "checksum error (001 5.2.4.2)"),
        (frame.encoder_error, "encoder error bit set in the frame")) if flag]
    if frame.power_failure:
        findings.insert(0, "POWER_FAILURE: the encoder's PowerFail bit is set (003)")
        if level < ERROR:
            return ERROR, "; ".join(findings)
    if not findings:
        return level, message
    if level < WARN:
        return WARN, "; ".join(findings)
    return level, "; ".join([message, *findings])


def bus_status(name: str, hardware_id: str, *, alive: bool, connected: bool,
               achieved_rate: float, publish_rate: float, counters: Mapping[str, object],
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
                   emcy: list[str], counters: Mapping[str, object]) -> DiagnosticStatus:
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


__all__ = ["ChannelCounters", "ChannelHealth", "bus_status", "channel_level", "channel_status",
           "station_status", "status_name"]
