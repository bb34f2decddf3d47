"""``--listen-only``: watch a bus another master drives, without sending a single frame.

What can be seen without asking: the gateways (heartbeats), and for a master that maps the
process input images as the node does (TPDO s = slot s's image, 000 Table 15 and
``client/sdo.py``) with REG_RD_ADR = REG_SSI_FRAME (the node's idle read), the raw frames of
each slot, so which bits move, the code and the direction. REG_PARA1 cannot be read without
the handshake, so no family is ranked and no params file is made.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import can

from ssi_bridge.commission.discover import Heard, note
from ssi_bridge.commission.infer import Motion, read_motion
from ssi_bridge.protocol.decode import XN_MAX_FRAME_BITS
from ssi_bridge.protocol.dictionary import MAX_SLOTS, tpdo_cob_base
from ssi_bridge.protocol.images import IMAGE_SIZE, ModuleStatus, ProcessInput
from ssi_bridge.protocol.registers import Reg


@dataclass
class Observation:
    """What watching showed: images per (node id, slot) and the frames they carried."""

    seconds: float
    images: dict[tuple[int, int], int] = field(default_factory=dict)
    frames: dict[tuple[int, int], list[int]] = field(default_factory=dict)
    err_ssi: dict[tuple[int, int], int] = field(default_factory=dict)

    def motions(self) -> dict[tuple[int, int], Motion]:
        """What the frames of each slot say (frame length unknown: the 32-bit register)."""
        return {key: read_motion(frames, XN_MAX_FRAME_BITS)
                for key, frames in sorted(self.frames.items()) if frames}


def observe(bus: can.BusABC, heard: Heard, seconds: float,
            say: Callable[[str], None]) -> Observation:
    """Receive for ``seconds``; collect heartbeats into ``heard`` and images per slot.

    :param bus: the open bus (nothing is sent on it)
    :param heard: what was heard so far (updated)
    :param seconds: how long to watch
    :param say: a progress line for a person
    """
    images = {tpdo_cob_base(s) + n: (n, s) for n in range(1, 128)
              for s in range(1, MAX_SLOTS + 1)}
    obs = Observation(seconds)
    say(f"listen-only: watching {seconds:g} s, nothing is sent")
    end = time.monotonic() + seconds
    while (left := end - time.monotonic()) > 0:
        try:
            msg = bus.recv(min(left, 0.1))
        except (can.CanError, OSError, ValueError):
            continue
        if msg is None:
            continue
        note(heard, msg)
        key = images.get(msg.arbitration_id)
        if key is None or len(msg.data) != IMAGE_SIZE or key[0] not in heard.heartbeats:
            continue
        image = ProcessInput.decode(bytes(msg.data))
        obs.images[key] = obs.images.get(key, 0) + 1
        if image.sts & ModuleStatus.ERR_SSI:
            obs.err_ssi[key] = obs.err_ssi.get(key, 0) + 1
        elif image.reg_rd_adr == Reg.REG_SSI_FRAME and not image.reg_rd_abort:
            obs.frames.setdefault(key, []).append(image.reg_rd_data)
    return obs


__all__ = ["Observation", "observe"]
