"""The simulated XI/ON station: per joint an encoder on its SSI line into an XN-1SSI module,
all behind an XN-GW-CANOPEN gateway on a CAN bus.

:class:`SimStation` wires the stages left of the gateway from the joints' settings (slots
without a joint hold a module with nothing connected). :class:`Station` adds the gateway and
the simulation-only objects (faults and motion epoch, 0x4000-0x4004,
:mod:`ssi_bridge.sim.gateway.simulation`), so a master reaches it only over the bus, like real
hardware, whether it runs in the master's process or in one of its own (``station``
executable, :mod:`ssi_bridge.sim.program`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import can

from ssi_bridge.protocol.joint_encoder import joint_config, para1_mismatch
from ssi_bridge.sim.encoder.encoder import SsiEncoder
from ssi_bridge.sim.encoder.motion import ConstantVelocity, MotionProfile, Sine, Still
from ssi_bridge.sim.gateway.gateway import XnGateway
from ssi_bridge.base.timebase import ModelClock
from ssi_bridge.protocol.settings import BusConfig, JointSettings, MotionSettings, StationSettings
from ssi_bridge.sim.gateway.simulation import SimulationControl
from ssi_bridge.sim.line.line import LineConfig, SsiLine
from ssi_bridge.sim.module.store import MemoryStore, RetentiveStore
from ssi_bridge.sim.module.xn1ssi import Xn1Ssi

logger = logging.getLogger(__name__)


def make_motion(m: MotionSettings) -> MotionProfile:
    """The motion profile a joint's simulated shaft follows (rev or m over seconds)."""
    if m.kind == "still":
        return Still(m.start)
    if m.kind == "sine":
        return Sine(m.amplitude, m.frequency, offset=m.start)
    return ConstantVelocity(m.velocity, start=m.start)


def joint_encoder(joint: JointSettings) -> SsiEncoder:
    """The simulated encoder of ``joint`` (family preset, overrides, motion)."""
    return SsiEncoder(joint_config(joint), make_motion(joint.motion))


@dataclass
class SimChannel:
    """One simulated joint: the encoder, its SSI line and the module it is wired to."""

    joint: JointSettings
    encoder: SsiEncoder
    line: SsiLine
    module: Xn1Ssi


class SimStation:
    """All simulated modules of one gateway station; ``modules[slot - 1]`` sits in slot 1-8.

    :param joints: the station's joints, each with its slot, encoder, cable and motion
    :param storage_path: where the retentive banks are kept (empty: in memory)
    """

    def __init__(self, joints: tuple[JointSettings, ...], storage_path: str = "") -> None:
        n_slots = max(j.slot for j in joints)
        self.channels: dict[str, SimChannel] = {}
        self.modules: list[Xn1Ssi] = []
        by_slot = {j.slot: j for j in joints}
        for slot in range(1, n_slots + 1):
            store = self._store(storage_path, slot)
            joint = by_slot.get(slot)
            if joint is None:
                self.modules.append(Xn1Ssi(None, store=store, slot=slot))
                continue
            encoder = joint_encoder(joint)
            line = SsiLine(encoder, LineConfig(cable_length_m=joint.cable_length))
            module = Xn1Ssi(line, store=store, slot=slot)
            self.modules.append(module)
            self.channels[joint.name] = SimChannel(joint, encoder, line, module)
            logger.info("slot %d: %s encoder (%d-bit %s frame) for joint %s", slot,
                        joint.family, encoder.frame_bits, encoder.config.code.name.lower(),
                        joint.name)
            mismatch = para1_mismatch(encoder.config, joint.para1)
            if mismatch:
                logger.warning("joint %s: REG_PARA1 0x%08X does not match the simulated %s "
                               "encoder: %s", joint.name, joint.para1, joint.family, mismatch)

    def channel_in_slot(self, slot: int) -> SimChannel | None:
        """The joint wired to module ``slot`` (1-8), or None."""
        for channel in self.channels.values():
            if channel.joint.slot == slot:
                return channel
        return None

    @staticmethod
    def _store(storage_path: str, slot: int) -> RetentiveStore | MemoryStore:
        """One retentive bank file per slot next to ``storage_path`` (or memory only).

        Saved without fsync: the atomic replace keeps the bank whole if the station is killed
        at any point, and a simulated module need not survive a power loss of the host. An
        fsync waits on the host's disk (seconds beside a busy test suite, docs/module.md), and a
        retentive write is answered over SDO only once saved: the station would fall silent
        for the master's SDO timeout (docs/module.md)."""
        if not storage_path:
            return MemoryStore()
        path = Path(storage_path).expanduser()
        path.parent.mkdir(parents=True, exist_ok=True)
        return RetentiveStore(path.with_name(f"{path.stem}.slot{slot}{path.suffix or '.bank'}"),
                              fsync=False)


class Station:
    """A simulated station on a bus: modules, gateway and the simulation fault objects.

    :param settings: joints, storage and the bus (a :class:`BusConfig` is opened here)
    :param bus: an open python-can bus to run on instead of ``settings.bus`` (taken over)
    """

    def __init__(self, settings: StationSettings, bus: can.BusABC | None = None) -> None:
        self.settings = settings
        #: the model clock: wire time since the station was built (base/timebase), the
        #: base its SYNC frames' timestamps latch the modules in
        self.model_clock = ModelClock()
        self.sim = SimStation(settings.joints, settings.storage_path)
        source: BusConfig | can.BusABC = settings.bus if bus is None else bus
        self.gateway = XnGateway(source, settings.bus.node_id, self.sim.modules,
                                 clock=self.model_clock)
        self.control = SimulationControl(self.sim, self.gateway)

    def clock(self) -> float:
        """Seconds since the station was built: the time the simulated shafts move on."""
        return self.model_clock()

    def start(self) -> None:
        """Join the bus and boot (boot-up message, PRE-OPERATIONAL); serve the fault objects."""
        self.gateway.start()
        self.control.start()

    def stop(self) -> None:
        """Stop serving and leave the bus (idempotent)."""
        self.control.stop()
        self.gateway.stop()
