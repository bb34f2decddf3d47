"""What an SSI master sees on the data line during one clock burst (the line -> module contract).

The XN-1SSI module (and any other master model) depends only on :class:`SsiReader`, so the
module can be unit-tested with a scripted reader and run on the real line model unchanged.

:class:`LineReadout` is a :class:`typing.NamedTuple`, not a frozen dataclass: it is built once
per burst in the scalar hot path (:meth:`SsiLine.read`), and a frozen dataclass pays an
``object.__setattr__`` per field (docs/encoder_line.md "Performance"). It is just as immutable,
attribute access is unchanged; use ``readout._replace(data=...)`` for a modified copy.
"""

from __future__ import annotations

from typing import NamedTuple, Protocol


class LineReadout(NamedTuple):
    """Levels the master read during one clock burst of ``n_bits + 1`` clocks (004 §2.2).

    ``start_bit`` is the level read on the first rising clock edge after the latch edge
    (the "pause 1" of 001 §4.6, 1 on a healthy line); ``data`` holds the ``n_bits`` bits read
    after it, MSB first (bit ``n_bits - 1`` of ``data`` is the first one read);
    ``trailer_bit`` is the level one clock period after the last data bit, which the master's
    ZERO test expects to be 0 while the encoder's monoflop holds the line low.
    """

    #: time of the first falling clock edge, where the encoder latches its value (s)
    latch_time: float
    #: number of data bits clocked after the start bit
    n_bits: int
    #: data bits, MSB first read = most significant bit of this integer
    data: int
    #: level read on the first clock (1 on a healthy line)
    start_bit: int = 1
    #: level read one clock after the last data bit (0 on a healthy line: monoflop time tm)
    trailer_bit: int = 0
    #: time the burst ended (last rising clock edge) (s)
    end_time: float = 0.0
    #: timing or protocol warnings with figures, e.g. "pause 12.0 us < tm 20.0 us"
    warnings: tuple[str, ...] = ()


class SsiReader(Protocol):
    """Anything that can clock one SSI frame: the line model, a replayed log, a test script."""

    def read(self, t: float, n_bits: int, bit_rate_hz: float) -> LineReadout:
        """Clock ``n_bits`` data bits starting at time ``t`` (s) at ``bit_rate_hz``."""
        ...
