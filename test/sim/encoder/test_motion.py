"""Motion profiles: exact ground truth (002: position, velocity, acceleration values)."""

from __future__ import annotations

import math

import pytest

from ssi_bridge.sim.encoder.motion import ConstantVelocity, Sine, Still, Trapezoid, Waypoints
from ssi_bridge.exceptions import ConfigError

H = 1e-6


def _num_deriv(f, t: float) -> float:
    return (f(t + H) - f(t - H)) / (2 * H)


@pytest.mark.parametrize("profile", [
    Still(3.25), ConstantVelocity(2.0, start=-1.0), Sine(0.5, 3.0, offset=1.0),
    Trapezoid(0.0, 10.0, v_max=4.0, accel=8.0, t0=0.1), Trapezoid(5.0, 4.0, 4.0, 8.0),
])
@pytest.mark.parametrize("t", [0.05, 0.13, 0.4, 1.0, 2.7])
def test_velocity_and_acceleration_are_derivatives(profile, t: float) -> None:
    """002 velocity/acceleration values: the ground truth is consistent with the position."""
    assert profile.velocity(t) == pytest.approx(_num_deriv(profile.position, t), abs=1e-5)
    assert profile.acceleration(t) == pytest.approx(_num_deriv(profile.velocity, t), abs=1e-3)


def test_trapezoid_reaches_target_and_rests() -> None:
    """A point-to-point move ends exactly at the target with zero speed."""
    p = Trapezoid(1.0, 3.0, v_max=1.0, accel=2.0)
    assert p.duration == pytest.approx(2.5)
    assert p.position(p.duration + 1.0) == 3.0
    assert p.velocity(1.0) == 1.0
    assert p.position(-1.0) == 1.0


def test_trapezoid_triangular_when_short() -> None:
    """Too short to reach v_max: peak speed sqrt(a * d)."""
    p = Trapezoid(0.0, 1.0, v_max=100.0, accel=4.0)
    assert max(p.velocity(i * 1e-3) for i in range(2000)) == pytest.approx(2.0, rel=1e-2)


def test_sine_values() -> None:
    s = Sine(2.0, 1.0, offset=0.5)
    assert s.position(0.25) == pytest.approx(2.5)
    assert s.velocity(0.0) == pytest.approx(4 * math.pi)


def test_waypoints_linear_script() -> None:
    """Waypoint script: linear between points, rest outside."""
    w = Waypoints([(0.0, 0.0), (1.0, 2.0), (3.0, 1.0)])
    assert w.position(0.5) == 1.0
    assert w.position(2.0) == 1.5
    assert w.velocity(2.0) == -0.5
    assert w.position(10.0) == 1.0 and w.velocity(10.0) == 0.0
    with pytest.raises(ConfigError):
        Waypoints([(1.0, 0.0), (1.0, 1.0)])
