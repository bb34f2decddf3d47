"""Multiple transmission (003, EL5002 "Multiple transmission mode").

The master sends 2 or 3 clock bursts within the monoflop time tm; the encoder sends the
same latched data word each time. The master compares the values:

* 2 bursts: equal -> the first value; different -> DATA_MISMATCH, the first value is still
  used as the counter value;
* 3 bursts: at least two of three must agree; the first valid value (the first that agrees
  with another) is the result; all different -> DATA_MISMATCH and the first value.

003 guarantees the function only for 15 µs < tm < 25 µs; the repeat bursts start one clock
period after the previous burst ends (``gap_periods``), which must still be inside tm.
"""

from __future__ import annotations

from dataclasses import dataclass

from ssi_bridge.exceptions import ConfigError
from ssi_bridge.protocol.decode import MasterStatus, check_readout
from ssi_bridge.sim.line.line import SsiLine
from ssi_bridge.protocol.readout import LineReadout


@dataclass(frozen=True)
class MultiReadout:
    """Result of one multiple transmission."""

    #: the readout whose value the master uses (first valid, else the first)
    readout: LineReadout
    #: every burst's readout, in order
    bursts: tuple[LineReadout, ...]
    #: 003 status (DATA_MISMATCH when the comparison failed, plus data/frame errors)
    status: MasterStatus

    @property
    def mismatch(self) -> bool:
        """Whether the repeated transmissions differed (DATA_MISMATCH)."""
        return bool(self.status & MasterStatus.DATA_MISMATCH)


class MultipleTransmission:
    """Reads an :class:`SsiLine` with 1, 2 or 3 bursts per sample (003 0x80n0 "Number of clock bursts").

    :param line: the line to read
    :param bursts: 1, 2 or 3
    :param gap_periods: clock periods between bursts
    :raises ConfigError: another number of bursts
    """

    def __init__(self, line: SsiLine, bursts: int = 2, gap_periods: float = 1.0) -> None:
        if bursts not in (1, 2, 3):
            raise ConfigError(f"number of clock bursts {bursts} must be 1, 2 or 3 (003)")
        self.line = line
        self.bursts = bursts
        self.gap_periods = gap_periods

    def read(self, t: float, n_bits: int, bit_rate_hz: float, *,
             zero_test: bool = True) -> MultiReadout:
        """Clock ``self.bursts`` bursts from ``t`` and compare their values.

        :param t: the first burst's start (s)
        :param n_bits: data bits per burst
        :param bit_rate_hz: the clock rate
        :param zero_test: check the bit after the frame is 0 (003 SB.1)
        """
        period = 1.0 / bit_rate_hz
        first = self.line.read(t, n_bits, bit_rate_hz)
        reads = [first]
        status = check_readout(first, zero_test=zero_test)
        for _ in range(self.bursts - 1):
            start = reads[-1].end_time + self.gap_periods * period
            r = self.line.read(start, n_bits, bit_rate_hz, expect_repeat=True)
            status |= check_readout(r, zero_test=zero_test, expect_start=False)
            reads.append(r)
        values = [r.data for r in reads]
        chosen = first
        if self.bursts == 2 and values[0] != values[1]:
            status |= MasterStatus.DATA_MISMATCH
        elif self.bursts == 3:
            valid = [i for i, v in enumerate(values) if values.count(v) >= 2]
            if valid:
                chosen = reads[valid[0]]
            else:
                status |= MasterStatus.DATA_MISMATCH
        return MultiReadout(chosen, tuple(reads), status)
