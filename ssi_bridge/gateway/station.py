"""The simulated XI/ON station: per joint an encoder on its SSI line into an XN-1SSI module,
all behind an XN-GW-CANOPEN gateway on a CAN bus.

:class:`SimStation` wires the stages left of the gateway from the joints' settings (slots
without a joint hold a module with nothing connected). :class:`Station` adds the gateway and
the simulation-only fault objects (0x4000-0x4003, :mod:`ssi_bridge.gateway.simulation`), so a
master reaches it only over the bus, like real hardware, whether it runs in the master's
process or in one of its own (``station`` executable, :mod:`ssi_bridge.tools.station`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import can

from ssi_bridge.encoder.codes import Code
from ssi_bridge.encoder.config import Alignment
from ssi_bridge.encoder.encoder import SsiEncoder
from ssi_bridge.encoder.families import make_encoder
from ssi_bridge.encoder.motion import ConstantVelocity, MotionProfile, Sine, Still
from ssi_bridge.gateway.bus import BusConfig
from ssi_bridge.gateway.gateway import XnGateway
from ssi_bridge.gateway.timebase import ModelClock
from ssi_bridge.gateway.settings import JointSettings, MotionSettings, StationSettings
from ssi_bridge.gateway.simulation import SimulationControl
from ssi_bridge.line.line import LineConfig, SsiLine
from ssi_bridge.module.registers import Para1
from ssi_bridge.module.store import MemoryStore, RetentiveStore
from ssi_bridge.module.xn1ssi import Xn1Ssi

logger = logging.getLogger(__name__)


def make_motion(m: MotionSettings) -> MotionProfile:
    """The motion profile a joint's simulated shaft follows (rev or m over seconds)."""
    if m.kind == "still":
        return Still(m.start)
    if m.kind == "sine":
        return Sine(m.amplitude, m.frequency, offset=m.start)
    return ConstantVelocity(m.velocity, start=m.start)


def encoder_overrides(joint: JointSettings) -> dict[str, Any]:
    """EncoderConfig fields a joint's parameters set on top of its family preset."""
    out: dict[str, Any] = {}
    if joint.code:
        out["code"] = Code.GRAY if joint.code == "gray" else Code.BINARY
    if joint.steps_per_rev:
        out["steps_per_rev"] = float(joint.steps_per_rev)
    if joint.revolutions:
        out["revolutions_numerator"] = int(joint.revolutions)
    if joint.measuring_step:
        out["measuring_step_m"] = float(joint.measuring_step)
    return out


def joint_encoder(joint: JointSettings) -> SsiEncoder:
    """The simulated encoder of ``joint`` (family preset, overrides, motion)."""
    return make_encoder(joint.family, make_motion(joint.motion), **encoder_overrides(joint))


def count_factor(encoder: SsiEncoder, para1: int) -> float:
    """REG_SSI_POS counts per encoder step for a REG_PARA1 reading this encoder.

    The encoder's position LSB sits ``frame_bits - position_bits`` bits before the end of its
    frame (special and filler bits follow, 004 §2.3; SSI-SHIFT-RIGHT loses one more). The
    module clocks SSI_FRAME_LEN bits — fewer cut the frame's end, more read 0s after it
    (004 §3.6) — then shifts INVALID_BITS_LSB out (000 Table 19). So the step lands at bit
    ``SSI_FRAME_LEN - frame_bits + lsb - INVALID_BITS_LSB`` of REG_SSI_POS. A Tannenbaum
    step field wider than the resolution ends in zeros (004 §3.4; the 16-bit step field of
    the TR check sum format, 001 §5.2.4.2): the whole value sits ``field - n`` bits higher.
    """
    cfg = encoder.config
    p = Para1.decode(para1)
    lsb = cfg.frame_bits - cfg.position_bits - (1 if cfg.shift_right else 0)
    if cfg.alignment is Alignment.TANNENBAUM and cfg.origin >= 0:
        lsb += cfg.data_bits - cfg.turn_bits - (int(cfg.steps_per_rev).bit_length() - 1)
    return 2.0 ** (p.ssi_frame_len - cfg.frame_bits + lsb - p.invalid_bits_lsb)


def para1_mismatch(encoder: SsiEncoder, para1: int) -> str | None:
    """Why REG_PARA1 does not fit the simulated encoder (a start-up warning), or None."""
    cfg = encoder.config
    p = Para1.decode(para1)
    problems = []
    if p.ssi_frame_len != cfg.frame_bits:
        problems.append(f"SSI_FRAME_LEN {p.ssi_frame_len} but the encoder sends {cfg.frame_bits} bits")
    if p.ssi_code_gray != (cfg.code is Code.GRAY):
        problems.append(f"SSI_CODE_G/D {'Gray' if p.ssi_code_gray else 'binary'} but the encoder sends "
                        f"{cfg.code.name.lower()}")
    return "; ".join(problems) or None


@dataclass
class SimChannel:
    """One simulated joint: the encoder, its SSI line and the module it is wired to."""

    joint: JointSettings
    encoder: SsiEncoder
    line: SsiLine
    module: Xn1Ssi


class SimStation:
    """All simulated modules of one gateway station; ``modules[slot - 1]`` sits in slot 1-8."""

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
            mismatch = para1_mismatch(encoder, joint.para1)
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
        """One retentive bank file per slot next to ``storage_path`` (or memory only)."""
        if not storage_path:
            return MemoryStore()
        path = Path(storage_path).expanduser()
        path.parent.mkdir(parents=True, exist_ok=True)
        return RetentiveStore(path.with_name(f"{path.stem}.slot{slot}{path.suffix or '.bank'}"))


class Station:
    """A simulated station on a bus: modules, gateway and the simulation fault objects.

    :param settings: joints, storage and the bus (a :class:`BusConfig` is opened here)
    :param bus: an open python-can bus to run on instead of ``settings.bus`` (taken over)
    """

    def __init__(self, settings: StationSettings, bus: can.BusABC | None = None) -> None:
        self.settings = settings
        #: the model clock: wire time since the station was built (gateway/timebase), the
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
