"""Shaft (or carriage) motion profiles: the exact ground truth behind every simulated frame.

A profile answers ``position(t)``, ``velocity(t)`` and ``acceleration(t)`` for any time ``t``
(s, on the injected clock). Units are revolutions, rev/s and rev/s² for a rotary encoder and
metres, m/s and m/s² for a linear one (TTK70, KH53). The velocity and acceleration are what
002 calls the position sensor's velocity/acceleration values; tests compare decoded frames
against these exact values, so every profile is closed-form (no integration drift).
"""

from __future__ import annotations

import bisect
import math
from abc import ABC, abstractmethod
from collections.abc import Sequence

from ssi_bridge.exceptions import ConfigError


class MotionProfile(ABC):
    """Position, velocity and acceleration as exact functions of time."""

    @abstractmethod
    def position(self, t: float) -> float:
        """Position at time ``t`` (rev or m)."""

    @abstractmethod
    def velocity(self, t: float) -> float:
        """Velocity at time ``t`` (rev/s or m/s)."""

    @abstractmethod
    def acceleration(self, t: float) -> float:
        """Acceleration at time ``t`` (rev/s² or m/s²)."""


class Still(MotionProfile):
    """A shaft at rest at ``position``."""

    def __init__(self, position: float = 0.0) -> None:
        self._p = float(position)

    def position(self, t: float) -> float:
        return self._p

    def velocity(self, t: float) -> float:
        return 0.0

    def acceleration(self, t: float) -> float:
        return 0.0


class ConstantVelocity(MotionProfile):
    """``position(t) = start + velocity * t``: ``start`` is the position at ``t = 0``."""

    def __init__(self, velocity: float, start: float = 0.0) -> None:
        self._v = float(velocity)
        self._p0 = float(start)

    def position(self, t: float) -> float:
        return self._p0 + self._v * t

    def velocity(self, t: float) -> float:
        return self._v

    def acceleration(self, t: float) -> float:
        return 0.0


class Sine(MotionProfile):
    """``position(t) = offset + amplitude * sin(2π f t)``: an oscillating axis.

    :param amplitude: rev or m
    :param frequency_hz: f (>= 0)
    :param offset: rev or m
    :raises ConfigError: a negative frequency
    """

    def __init__(self, amplitude: float, frequency_hz: float, offset: float = 0.0) -> None:
        if frequency_hz < 0:
            raise ConfigError(f"Sine frequency_hz {frequency_hz} must be >= 0")
        self._a = float(amplitude)
        self._w = 2.0 * math.pi * float(frequency_hz)
        self._off = float(offset)

    def position(self, t: float) -> float:
        return self._off + self._a * math.sin(self._w * t)

    def velocity(self, t: float) -> float:
        return self._a * self._w * math.cos(self._w * t)

    def acceleration(self, t: float) -> float:
        return -self._a * self._w * self._w * math.sin(self._w * t)


class Trapezoid(MotionProfile):
    """A point-to-point move from ``start`` to ``end`` with a trapezoidal velocity profile.

    Accelerates at ``accel`` up to ``v_max``, cruises, decelerates at ``accel``; the move
    begins at ``t0``. When the distance is too short to reach ``v_max`` the profile is
    triangular. Before ``t0`` the axis rests at ``start``, after the move at ``end``.

    :raises ConfigError: ``v_max`` or ``accel`` not positive
    """

    def __init__(self, start: float, end: float, v_max: float, accel: float,
                 t0: float = 0.0) -> None:
        if v_max <= 0 or accel <= 0:
            raise ConfigError(f"Trapezoid v_max {v_max} and accel {accel} must be > 0")
        self._p0, self._p1, self._t0 = float(start), float(end), float(t0)
        dist = abs(self._p1 - self._p0)
        self._dir = 1.0 if self._p1 >= self._p0 else -1.0
        self._a = float(accel)
        t_acc = v_max / accel
        if accel * t_acc * t_acc >= dist:        # triangular: never reaches v_max
            t_acc = math.sqrt(dist / accel)
            self._vp = accel * t_acc
            t_cruise = 0.0
        else:
            self._vp = float(v_max)
            t_cruise = (dist - accel * t_acc * t_acc) / v_max
        self._ta, self._tc = t_acc, t_cruise
        self.duration = 2.0 * t_acc + t_cruise

    def _state(self, t: float) -> tuple[float, float, float]:
        """Signed (distance travelled, speed, acceleration) at ``t``."""
        tau = t - self._t0
        a, ta, tc, vp = self._a, self._ta, self._tc, self._vp
        if tau <= 0.0:
            return 0.0, 0.0, 0.0
        if tau < ta:
            return 0.5 * a * tau * tau, a * tau, a
        d_acc = 0.5 * a * ta * ta
        if tau < ta + tc:
            return d_acc + vp * (tau - ta), vp, 0.0
        td = tau - ta - tc
        if td < ta:
            return d_acc + vp * tc + vp * td - 0.5 * a * td * td, vp - a * td, -a
        return abs(self._p1 - self._p0), 0.0, 0.0

    def position(self, t: float) -> float:
        return self._p0 + self._dir * self._state(t)[0]

    def velocity(self, t: float) -> float:
        return self._dir * self._state(t)[1]

    def acceleration(self, t: float) -> float:
        return self._dir * self._state(t)[2]


class Waypoints(MotionProfile):
    """A scripted path through ``(time, position)`` points, linear between them.

    Velocity is the constant slope of the current segment (at a knot, the segment that
    starts there); acceleration is 0 between knots (it is an impulse at the knots, which a
    piecewise-linear script cannot represent). Before the first point and after the last
    the axis rests there.

    :param points: ``(time s, position)`` pairs, times strictly increasing
    :raises ConfigError: no point, or times that do not increase
    """

    def __init__(self, points: Sequence[tuple[float, float]]) -> None:
        if not points:
            raise ConfigError("Waypoints needs at least one (time, position) point")
        times = [float(p[0]) for p in points]
        if any(b <= a for a, b in zip(times, times[1:])):
            raise ConfigError(f"Waypoints times must increase strictly, got {times}")
        self._t = times
        self._p = [float(p[1]) for p in points]

    def _segment(self, t: float) -> int:
        """Index i of the segment [t_i, t_i+1) containing t, or -1 / len-1 outside."""
        return bisect.bisect_right(self._t, t) - 1

    def position(self, t: float) -> float:
        i = self._segment(t)
        if i < 0:
            return self._p[0]
        if i >= len(self._t) - 1:
            return self._p[-1]
        t0, t1, p0, p1 = self._t[i], self._t[i + 1], self._p[i], self._p[i + 1]
        return p0 + (p1 - p0) * (t - t0) / (t1 - t0)

    def velocity(self, t: float) -> float:
        i = self._segment(t)
        if i < 0 or i >= len(self._t) - 1:
            return 0.0
        return (self._p[i + 1] - self._p[i]) / (self._t[i + 1] - self._t[i])

    def acceleration(self, t: float) -> float:
        return 0.0
