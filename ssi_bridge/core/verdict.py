"""What a station's frame log (``core/cycle_log.StationLog``) says of one slot at one of the
master's SYNCs: the sample it vouches for as latched at the SYNC, or why it set it aside.

ROS-free and free of any bus library, like the log.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(slots=True)  # read-only by convention: frozen would cost 2x per instance
class VouchedSample:
    """A slot's sample latched at the master's SYNC (within ``latch_bound``)."""

    slot: int
    #: REG_SSI_POS as Integer32 (object 0x6820)
    position: int
    #: the 8-byte process input image (000 "Process input")
    process_input: bytes
    #: the SYNC's wire time (s): the stamp
    sync_time: float
    #: process input images received for this slot
    counter: int
    #: the earlier of the two frames' wire times minus ``sync_time`` (s): the latch lies
    #: between ``sync_time`` and ``sync_time + delay``
    delay: float


@dataclass(slots=True)  # read-only by convention: frozen would cost 2x per instance
class Verdict:
    """What the log says of one slot at one of the master's SYNCs."""

    #: the sample, or None when set aside
    sample: VouchedSample | None
    #: "" when vouched, else one of ``core/cycle_log.REASONS``
    reason: str
    #: share of the slot's two TPDOs of the window that never came (0, 0.5, 1)
    missing: float
    #: the newest image of the slot in the window (b"" if none), for the status bits
    image: bytes = b""
    #: the newest position in the window (None if none)
    position: int | None = None


#: a :class:`Verdict`'s fields as a plain tuple, in its order (sample, reason, missing, image,
#: position): what ``StationLog.answers`` (``core/cycle_log.py``) gives the cycle, one per slot
Answer = tuple[VouchedSample | None, str, float, bytes, int | None]


__all__ = ["Answer", "Verdict", "VouchedSample"]
