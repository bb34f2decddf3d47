"""Fault injection into the simulated station (the ``~/inject_fault`` service's backend).

Each fault acts where a real one would: a broken wire or noise on the SSI line, an error or
power-failure bit in the encoder, an invalid REG_PARA1 set at the module's parameter
interface (ERR_PARA), lost CAN frames or a silent gateway on the bus. Faults
with a duration clear themselves; ``CLEAR_ALL`` clears everything. ROS-free.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from enum import IntEnum

from ssi_bridge.encoder.config import ERROR_BITS, SpecialBit
from ssi_bridge.exceptions import ConfigError
from ssi_bridge.ros.station import SimStation

logger = logging.getLogger(__name__)


class FaultKind(IntEnum):
    """Fault kinds, numbered as the constants of ssi_bridge_msgs/srv/InjectFault."""

    CLEAR_ALL = 0
    DATA_WIRE_BREAK = 1
    CLOCK_WIRE_BREAK = 2
    ENCODER_ERROR = 3
    POWER_FAILURE = 4
    BIT_NOISE = 5
    CAN_FRAME_LOSS = 6
    GATEWAY_SILENT = 7
    INVALID_PARA1 = 8


#: faults of the bus or gateway (the joint is ignored)
BUS_FAULTS = (FaultKind.CAN_FRAME_LOSS, FaultKind.GATEWAY_SILENT)


@dataclass(frozen=True)
class ActiveFault:
    """A fault in force: what, where, and when it ends (clock time, None = until cleared)."""

    kind: FaultKind
    joint: str
    rate: float
    until: float | None


def _visibility_note(fault: FaultKind, channel: object) -> str:
    """Say when the encoder's frame layout has no bit that could show the fault."""
    if channel is None:
        return ""
    cfg = channel.encoder.config  # type: ignore[attr-defined]
    bits = set(cfg.special_bits)
    if fault is FaultKind.POWER_FAILURE and SpecialBit.POWER_FAIL not in bits:
        return (f"the {cfg.name} frame has no power-fail bit (003), so nothing on the wire "
                "changes")
    if fault is FaultKind.ENCODER_ERROR and not bits & ERROR_BITS:
        return (f"the {cfg.name} frame has no error bit (004 §2.3); it shows only where the "
                "family sends an error value")
    return ""


class FaultInjector:
    """Applies and clears faults on a :class:`SimStation` and its gateway."""

    def __init__(self, station: SimStation, gateway: object, clock: Callable[[], float]) -> None:
        self._station = station
        self._gateway = gateway
        self._clock = clock
        self.active: list[ActiveFault] = []

    def inject(self, kind: int, joint: str, rate: float = 0.0, duration: float = 0.0) -> str:
        """Apply a fault and return a sentence saying what now happens; raises ConfigError."""
        try:
            fault = FaultKind(kind)
        except ValueError:
            raise ConfigError(
                f"unknown fault kind {kind}; kinds: "
                + ", ".join(f"{k.value}={k.name}" for k in FaultKind)) from None
        if not math.isfinite(duration) or duration < 0:
            raise ConfigError(f"duration {duration} s must be finite and >= 0 (0 = until cleared)")
        if fault in (FaultKind.BIT_NOISE, FaultKind.CAN_FRAME_LOSS):
            if not (math.isfinite(rate) and 0.0 < rate <= 1.0):
                raise ConfigError(f"{fault.name} needs a rate in (0, 1], got {rate}")
        if fault is FaultKind.CLEAR_ALL:
            self.clear_all()
            return "all faults cleared"
        channel = None
        if fault not in BUS_FAULTS:
            if joint not in self._station.channels:
                raise ConfigError(f"unknown joint {joint!r}; joints: "
                                  + ", ".join(self._station.channels))
            channel = self._station.channels[joint]
        self._apply(fault, channel, rate, on=True)
        until = self._clock() + duration if duration > 0 else None
        self.active.append(ActiveFault(fault, joint if channel else "", rate, until))
        where = f"joint {joint}" if channel else "the bus"
        span = f"for {duration:g} s" if until is not None else "until CLEAR_ALL"
        logger.warning("fault injected: %s on %s %s", fault.name, where, span)
        note = _visibility_note(fault, channel)
        return f"{fault.name} injected on {where} {span}" + (f"; {note}" if note else "")

    def expire(self) -> list[ActiveFault]:
        """Clear faults whose duration has run out; returns the ones cleared."""
        now = self._clock()
        done = [f for f in self.active if f.until is not None and now >= f.until]
        for fault in done:
            self.active.remove(fault)
            channel = self._station.channels.get(fault.joint)
            self._apply(fault.kind, channel, fault.rate, on=False)
            logger.info("fault %s on %s cleared after its duration", fault.kind.name,
                        fault.joint or "the bus")
        return done

    def clear_all(self) -> None:
        """Remove every injected fault."""
        for fault in list(self.active):
            self._apply(fault.kind, self._station.channels.get(fault.joint), fault.rate, on=False)
        self.active.clear()

    def _apply(self, kind: FaultKind, channel: object, rate: float, *, on: bool) -> None:
        gateway = self._gateway
        if kind is FaultKind.GATEWAY_SILENT:
            gateway.silent = on  # type: ignore[attr-defined]
        elif kind is FaultKind.CAN_FRAME_LOSS:
            gateway.bus.loss_rate = rate if on else 0.0  # type: ignore[attr-defined]
        elif kind is FaultKind.DATA_WIRE_BREAK:
            channel.line.faults.data_break = on  # type: ignore[attr-defined]
        elif kind is FaultKind.CLOCK_WIRE_BREAK:
            channel.line.faults.clock_break = on  # type: ignore[attr-defined]
        elif kind is FaultKind.BIT_NOISE:
            channel.line.faults.bit_error_rate = rate if on else 0.0  # type: ignore[attr-defined]
        elif kind is FaultKind.ENCODER_ERROR:
            channel.encoder.set_error(on)  # type: ignore[attr-defined]
        elif kind is FaultKind.POWER_FAILURE:
            channel.encoder.power_failure = on  # type: ignore[attr-defined]
        elif kind is FaultKind.INVALID_PARA1:
            # an invalid set at the module's parameter interface, past the node's own check
            module = channel.module  # type: ignore[attr-defined]
            if on:
                module.inject_parameter_error()
            else:
                module.clear_parameter_error()
