"""Counts to joint units: REG_SSI_POS as rad (rotary) or m (linear), and back.

ROS-free so it is unit-tested with exact numbers. Position is REG_SSI_POS read as the
Integer32 of object 0x6820 (000, Table 40), so a preset that moves the zero point below the
encoder's value gives a negative position instead of a jump to 4 294 967 295 steps.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ssi_bridge.exceptions import ConfigError


def to_int32(value: int) -> int:
    """Read a 32-bit register value as the Integer32 of CANopen object 0x6820."""
    value &= 0xFFFF_FFFF
    return value - (1 << 32) if value & 0x8000_0000 else value


@dataclass(frozen=True)
class JointScale:
    """How one count of REG_SSI_POS maps to joint units (rad for rotary, m for linear)."""

    #: counts per revolution as REG_SSI_POS sees them (after INVALID_BITS_LSB shifting)
    counts_per_rev: float = 8192.0
    #: distinguishable revolutions (the multiturn range); counts wrap at counts_per_rev * this
    revolutions: float = 4096.0
    #: linear encoder: one count is ``measuring_step_m`` metres and the joint unit is m
    linear: bool = False
    #: metres per count for linear encoders
    measuring_step_m: float = 1e-6
    #: +1 or -1: flips the joint's sign against the count direction (mounting)
    direction: int = 1

    def __post_init__(self) -> None:
        if self.linear:
            if not self.measuring_step_m > 0:
                raise ConfigError(f"measuring_step_m {self.measuring_step_m} must be > 0")
        elif not (self.counts_per_rev > 0 and self.revolutions >= 1):
            raise ConfigError(
                f"counts_per_rev {self.counts_per_rev} must be > 0 and revolutions "
                f"{self.revolutions} >= 1")
        if self.direction not in (1, -1):
            raise ConfigError(f"direction {self.direction} must be 1 or -1")

    @property
    def unit_per_count(self) -> float:
        """Joint units (rad or m) per count, signed by ``direction``."""
        base = self.measuring_step_m if self.linear else 2.0 * math.pi / self.counts_per_rev
        return base * self.direction

    @property
    def modulus(self) -> int | None:
        """Counts after which the encoder value wraps (rotary), None for linear encoders."""
        if self.linear:
            return None
        return int(round(self.counts_per_rev * self.revolutions))

    def position(self, counts: int) -> float:
        """Joint position of a REG_SSI_POS value (32-bit, read as Integer32).

        :param counts: REG_SSI_POS as received
        :returns: rad (rotary) or m (linear)
        """
        return to_int32(counts) * self.unit_per_count

    def counts(self, position: float) -> int:
        """Nearest count for a joint position (inverse of :meth:`position`)."""
        return int(round(position / self.unit_per_count))
