"""Fault injection into the simulated station (the ``~/inject_fault`` service's backend).

The node reaches its station only over CAN, faults included: a request becomes SDO writes
of the station's simulation-only objects 0x4000 (rate), 0x4001 (duration, ms) and 0x4002
(command = kind | slot << 8), served by :mod:`ssi_bridge.sim.gateway.simulation`. The station
times durations itself; this side keeps a mirror of what it asked for, to say when a fault
ended and to refuse what a silent gateway cannot hear. ROS-free.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

from ssi_bridge.protocol.encoder_config import ERROR_BITS, EncoderConfig, SpecialBit
from ssi_bridge.exceptions import ConfigError
from ssi_bridge.protocol.dictionary import SIM_COMMAND, SIM_DURATION, SIM_RATE
from ssi_bridge.protocol.settings import JointSettings
from ssi_bridge.sim.gateway.simulation import (
    BUS_FAULTS, MUTING_FAULTS, RATE_FAULTS, FaultKind, command_word,
)

logger = logging.getLogger(__name__)

__all__ = ["ActiveFault", "BUS_FAULTS", "FaultInjector", "FaultKind", "StationFaults"]

#: largest duration 0x4001 holds (UNSIGNED32 ms)
MAX_DURATION = (2**32 - 1) / 1000.0


class ObjectWriter(Protocol):
    """The master's SDO access (BridgeClient)."""

    def write_object(self, index: int, subindex: int, value: int | float | bytes) -> None:
        """SDO download of ``value`` to ``index``:``subindex`` (raises SsiBridgeError)."""


@dataclass(frozen=True)
class ActiveFault:
    """A fault in force: what, where, and when it ends (clock time, None = until cleared)."""

    kind: FaultKind
    joint: str
    rate: float
    until: float | None


def _visibility_note(fault: FaultKind, cfg: EncoderConfig | None) -> str:
    """Say when the encoder's frame layout has no bit that could show the fault."""
    if cfg is None:
        return ""
    bits = set(cfg.special_bits)
    if fault is FaultKind.POWER_FAILURE and SpecialBit.POWER_FAIL not in bits:
        return (f"the {cfg.name} frame has no power-fail bit (003), so nothing on the wire "
                "changes")
    if fault is FaultKind.ENCODER_ERROR and not bits & ERROR_BITS:
        return (f"the {cfg.name} frame has no error bit (004 §2.3); it shows only where the "
                "family sends an error value")
    return ""


class FaultInjector:
    """Sends faults to the simulated station over SDO and mirrors what is in force.

    :param client: the master's SDO access to the station
    :param joints: the node's joints (name -> settings: the slot the fault goes to)
    :param configs: the joints' encoder layouts (None: unknown)
    :param clock: the node's clock for the mirror of durations (s)
    """

    def __init__(self, client: ObjectWriter, joints: dict[str, JointSettings],
                 configs: dict[str, EncoderConfig | None], clock: Callable[[], float]) -> None:
        self._client = client
        self._joints = joints
        self._configs = configs
        self._clock = clock
        self.active: list[ActiveFault] = []

    def inject(self, kind: int, joint: str, rate: float = 0.0, duration: float = 0.0) -> str:
        """Apply a fault and return a sentence saying what now happens; raises ConfigError.

        :param kind: the fault (``InjectFault`` constants; 0 clears all)
        :param joint: the joint whose encoder, line or module is faulted (empty: the first)
        :param rate: probability per frame or cycle, where the kind has one
        :param duration: seconds, 0 = until cleared
        """
        try:
            fault = FaultKind(kind)
        except ValueError:
            raise ConfigError(
                f"unknown fault kind {kind}; kinds: "
                + ", ".join(f"{k.value}={k.name}" for k in FaultKind)) from None
        if not math.isfinite(duration) or duration < 0 or duration > MAX_DURATION:
            raise ConfigError(f"duration {duration} s must be finite and 0-{MAX_DURATION:g} "
                              "(0 = until cleared)")
        if fault in RATE_FAULTS and not (math.isfinite(rate) and 0.0 < rate <= 1.0):
            raise ConfigError(f"{fault.name} needs a rate in (0, 1], got {rate}")
        if fault is FaultKind.CLEAR_ALL:
            # one expedited write: a silent station applies it before it answers (and unmutes)
            self._client.write_object(SIM_COMMAND, 0, command_word(FaultKind.CLEAR_ALL, 0))
            self.active.clear()
            return "all faults cleared"
        slot = 0
        if fault not in BUS_FAULTS:
            if joint not in self._joints:
                raise ConfigError(f"unknown joint {joint!r}; joints: " + ", ".join(self._joints))
            slot = self._joints[joint].slot
        self.expire()
        muted = [f.kind.name for f in self.active if f.kind in MUTING_FAULTS]
        if muted:
            raise ConfigError(f"the gateway is silent ({muted[0]} in force) and answers "
                              "nothing: only CLEAR_ALL reaches it")
        rate_value = float(rate) if fault in RATE_FAULTS else 0.0
        duration_ms = max(1, round(duration * 1000)) if duration > 0 else 0
        self._client.write_object(SIM_RATE, 0, rate_value)
        self._client.write_object(SIM_DURATION, 0, duration_ms)
        self._client.write_object(SIM_COMMAND, 0, command_word(fault, slot))
        until = self._clock() + duration if duration > 0 else None
        self.active.append(ActiveFault(fault, joint if slot else "", rate_value, until))
        where = f"joint {joint}" if slot else "the bus"
        span = f"for {duration:g} s" if until is not None else "until CLEAR_ALL"
        logger.warning("fault injected: %s on %s %s", fault.name, where, span)
        note = _visibility_note(fault, self._configs.get(joint) if slot else None)
        return f"{fault.name} injected on {where} {span}" + (f"; {note}" if note else "")

    def expire(self) -> list[ActiveFault]:
        """Forget faults whose duration has run out (the station clears them itself)."""
        now = self._clock()
        done = [f for f in self.active if f.until is not None and now >= f.until]
        for fault in done:
            self.active.remove(fault)
            logger.info("fault %s on %s cleared after its duration", fault.kind.name,
                        fault.joint or "the bus")
        return done

    def clear_all(self) -> None:
        """Remove every injected fault (CLEAR_ALL over the bus)."""
        self.inject(FaultKind.CLEAR_ALL, "")


class StationFaults:
    """Fault injection into several simulated stations: each joint's fault goes to its own.

    A fault on a joint (GATEWAY_SILENT included) is sent to the station holding that joint's
    module; CLEAR_ALL goes to every station; a bus fault without a joint to the first one.

    :param injectors: one :class:`FaultInjector` per station node id, first station first
    :param joints: the node's joints (their ``station``)
    """

    def __init__(self, injectors: dict[int, FaultInjector],
                 joints: dict[str, JointSettings]) -> None:
        self._injectors = injectors
        self._joints = joints

    @property
    def active(self) -> list[ActiveFault]:
        """The faults in force on every station."""
        return [f for inj in self._injectors.values() for f in inj.active]

    def inject(self, kind: int, joint: str, rate: float = 0.0, duration: float = 0.0) -> str:
        """Route the fault to the joint's station (see :meth:`FaultInjector.inject`).

        Parameters ``kind``, ``joint``, ``rate`` and ``duration`` as there.

        :raises ConfigError: ``joint`` is no joint of any station
        """
        if kind == FaultKind.CLEAR_ALL:
            for inj in self._injectors.values():
                inj.inject(kind, joint, rate, duration)
            return "all faults cleared on " + ", ".join(
                f"station {sid}" for sid in self._injectors)
        if joint in self._joints:
            sid = self._joints[joint].station
        elif joint:
            raise ConfigError(f"unknown joint {joint!r}; joints: " + ", ".join(self._joints))
        else:
            sid = next(iter(self._injectors))
        return f"station {sid}: " + self._injectors[sid].inject(kind, joint, rate, duration)

    def expire(self) -> list[ActiveFault]:
        """Forget faults whose duration has run out, on every station."""
        return [f for inj in self._injectors.values() for f in inj.expire()]

    def clear_all(self) -> None:
        """CLEAR_ALL on every station."""
        self.inject(FaultKind.CLEAR_ALL, "")
