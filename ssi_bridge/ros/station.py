"""The simulated XI/ON station: per joint an encoder on its SSI line into an XN-1SSI module.

ROS-free wiring of the stages left of the gateway, built from the node's settings. The
gateway gets :attr:`SimStation.modules` (one per slot, slots without a joint hold a module
with nothing connected) and runs them on SYNC; the node reaches the simulated hardware only
through the bus, except for fault injection, which acts here like a hand on the cable.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

from ssi_bridge.encoder.encoder import SsiEncoder
from ssi_bridge.encoder.families import make_encoder
from ssi_bridge.encoder.motion import ConstantVelocity, MotionProfile, Sine, Still
from ssi_bridge.line.line import SsiLine
from ssi_bridge.module.store import MemoryStore, RetentiveStore
from ssi_bridge.module.xn1ssi import Xn1Ssi
from ssi_bridge.ros.params import JointSettings, MotionSettings, NodeSettings

logger = logging.getLogger(__name__)


def make_motion(m: MotionSettings) -> MotionProfile:
    """The motion profile a joint's simulated shaft follows (rev or m over seconds)."""
    if m.kind == "still":
        return Still(m.start)
    if m.kind == "sine":
        return Sine(m.amplitude, m.frequency, offset=m.start)
    return ConstantVelocity(m.velocity, start=m.start)


@dataclass
class SimChannel:
    """One simulated joint: the encoder, its SSI line and the module it is wired to."""

    joint: JointSettings
    encoder: SsiEncoder
    line: SsiLine
    module: Xn1Ssi


class SimStation:
    """All simulated modules of one gateway station; ``modules[slot - 1]`` sits in slot 1-8."""

    def __init__(self, settings: NodeSettings) -> None:
        n_slots = max(j.slot for j in settings.joints)
        self.channels: dict[str, SimChannel] = {}
        self.modules: list[Xn1Ssi] = []
        by_slot = {j.slot: j for j in settings.joints}
        for slot in range(1, n_slots + 1):
            store = self._store(settings.storage_path, slot)
            joint = by_slot.get(slot)
            if joint is None:
                self.modules.append(Xn1Ssi(None, store=store, slot=slot))
                continue
            encoder = make_encoder(joint.family, make_motion(joint.motion))
            line = SsiLine(encoder)
            module = Xn1Ssi(line, store=store, slot=slot)
            self.modules.append(module)
            self.channels[joint.name] = SimChannel(joint, encoder, line, module)
            logger.info("slot %d: %s encoder (%d-bit frame) for joint %s", slot, joint.family,
                        encoder.frame_bits, joint.name)

    @staticmethod
    def _store(storage_path: str, slot: int) -> RetentiveStore | MemoryStore:
        """One retentive bank file per slot next to ``storage_path`` (or memory only)."""
        if not storage_path:
            return MemoryStore()
        path = Path(storage_path).expanduser()
        path.parent.mkdir(parents=True, exist_ok=True)
        return RetentiveStore(path.with_name(f"{path.stem}.slot{slot}{path.suffix or '.bank'}"))
