"""What a slot table hands on of every frame it sees: the cycle's frame log, as a protocol.

The client does not import the cycle core (``.importlinter``: the order inside the driver);
the node passes the core's ``StationLog`` in as a :class:`FrameSink`, which it satisfies by
its shape.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol


class FrameSink(Protocol):
    """Where a slot table hands every SYNC and TPDO it sees, with its wire time: the cycle's
    frame log (``core/cycle_log.StationLog``), which decides which SYNC a sample answers.

    Called under the table's lock, from the receive thread (frames, foreign SYNCs) and the
    cycle thread (own SYNCs); an implementation must be quick and must not call back.
    """

    def sync(self, seq: int, t: float) -> None:
        """The master's SYNC ``seq`` at wire time ``t`` (again, once its exact time is known)."""

    def foreign_sync(self, t: float) -> None:
        """Another producer's SYNC at wire time ``t``."""

    def image(self, slot: int, t: float, data: bytes | bytearray, count: int) -> None:
        """A process input image of ``slot`` (the ``count``-th) at wire time ``t``.

        :param data: the 8 bytes of the image
        """

    def position(self, slot: int, t: float, value: int) -> None:
        """A position of ``slot`` at wire time ``t``.

        :param value: REG_SSI_POS as received
        """

    def positions(self, slots: Sequence[int], t: float, values: Sequence[int]) -> None:
        """The positions of ``slots`` (one encoder default PDO) at wire time ``t``: what
        :meth:`position` of each, with the value of ``values`` at the same index, does.
        """


__all__ = ["FrameSink"]
