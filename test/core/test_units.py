"""Counts -> joint units and the velocity estimate (ROS-free, exact numbers)."""

from __future__ import annotations

import math

import pytest

from ssi_bridge.exceptions import ConfigError
from ssi_bridge.core.joint_scale import JointScale, to_int32
from ssi_bridge.core.velocity import VelocityEstimator


@pytest.mark.parametrize("raw, signed", [
    (0, 0), (1, 1), (0x7FFF_FFFF, 2**31 - 1), (0x8000_0000, -(2**31)), (0xFFFF_FFFF, -1),
])
def test_reg_ssi_pos_is_read_as_integer32_of_object_6820(raw, signed):
    # 000 Table 40: object 0x6820 (REG_SSI_POS) has data type Integer32
    assert to_int32(raw) == signed


def test_rotary_scale_full_turn_is_two_pi():
    scale = JointScale(counts_per_rev=8192, revolutions=4096)
    assert scale.position(8192) == pytest.approx(2 * math.pi)
    assert scale.position(0xFFFF_FFFF) == pytest.approx(-2 * math.pi / 8192)
    assert scale.counts(math.pi) == 4096
    assert scale.modulus == 8192 * 4096


def test_linear_scale_and_direction():
    scale = JointScale(linear=True, measuring_step_m=1e-6, direction=-1)
    assert scale.position(1000) == pytest.approx(-1e-3)
    assert scale.modulus is None


@pytest.mark.parametrize("kwargs", [
    dict(counts_per_rev=0), dict(revolutions=0.5), dict(direction=2),
    dict(linear=True, measuring_step_m=0.0),
])
def test_invalid_scales_are_refused(kwargs):
    with pytest.raises(ConfigError):
        JointScale(**kwargs)


def test_velocity_exact_for_constant_speed_and_across_the_multiturn_wrap():
    scale = JointScale(counts_per_rev=8192, revolutions=4096)
    est = VelocityEstimator(scale, window=5)
    modulus = scale.modulus
    speed_counts = 2048.0  # counts/s = 0.25 rev/s
    start = modulus - 100  # crosses the wrap of the 25-bit value after ~0.05 s
    v = 0.0
    for k in range(50):
        t = k * 0.01
        v = est.update(t, int(start + speed_counts * t) % modulus)
    assert v == pytest.approx(2 * math.pi * 0.25, rel=1e-3)


def test_velocity_unknown_nan_before_two_samples_and_after_reset():
    # docs/node.md: an unknown speed is NaN, never a made-up 0.0
    est = VelocityEstimator(JointScale(), window=3)
    assert math.isnan(est.velocity)
    assert math.isnan(est.update(0.0, 10))
    assert est.update(0.1, 20) == pytest.approx(10 / 0.1 * 2 * math.pi / 8192)
    est.reset()
    assert math.isnan(est.velocity)
    assert math.isnan(est.update(0.2, 30)), "one sample after a reset is not a speed"
    assert not math.isnan(est.update(0.3, 40))


def test_window_below_two_is_refused():
    with pytest.raises(ConfigError):
        VelocityEstimator(JointScale(), window=1)


def test_samples_latched_before_a_reset_time_are_ignored():
    scale = JointScale(counts_per_rev=8192, revolutions=4096)
    est = VelocityEstimator(scale, window=3)
    for k in range(3):
        est.update(k * 0.01, 1000 + 100 * k)
    est.reset(after=0.025)
    # a late sample from before the preset (old zero point) must not enter the estimate
    assert math.isnan(est.update(0.02, 1200))
    est.update(0.03, 10)
    assert est.update(0.04, 110) == pytest.approx(100 / 0.01 * scale.unit_per_count)


def test_hold_keeps_the_speed_through_a_preset():
    scale = JointScale(counts_per_rev=8192, revolutions=4096)
    est = VelocityEstimator(scale, window=3)
    for k in range(3):
        est.update(k * 0.01, 1000 + 100 * k)
    speed = est.velocity
    est.reset(after=float("inf"), hold=True)
    assert est.update(0.03, 5) == speed, "samples during the preset are ignored, speed held"
    est.reset(after=0.035, hold=True)
    assert est.update(0.04, 10) == speed, "one new sample is not enough: still held"
    assert est.update(0.05, 110) == pytest.approx(speed), "then the fresh estimate"


def test_a_jump_beyond_max_speed_is_nan_and_restarts_the_window():
    scale = JointScale(counts_per_rev=8192, revolutions=4096)
    step = 2 * math.pi / 8192
    # 1 rad/s limit at 100 Hz: at most 0.01 rad = 13 counts per sample
    est = VelocityEstimator(scale, window=3, max_speed=1.0)
    for k in range(4):
        est.update(k * 0.01, 1000 + 10 * k)  # 10 counts / 10 ms = 0.77 rad/s: plausible
    assert est.velocity == pytest.approx(10 / 0.01 * step)
    assert est.implausible == 0
    assert math.isnan(est.update(0.04, 1030 + 500)), "a 500-count jump in 10 ms is 38 rad/s"
    assert est.last_implausible and est.implausible == 1
    # the estimate restarts at the jumped-to value: the next step is plausible again
    assert est.update(0.05, 1540) == pytest.approx(10 / 0.01 * step)
    assert not est.last_implausible


def test_max_speed_zero_is_off_and_negative_is_refused():
    est = VelocityEstimator(JointScale(), window=2, max_speed=0.0)
    est.update(0.0, 0)
    assert est.update(0.01, 1_000_000) > 0 and est.implausible == 0
    with pytest.raises(ConfigError):
        VelocityEstimator(JointScale(), max_speed=-1.0)


def test_the_wrap_of_a_multiturn_value_is_not_a_jump():
    scale = JointScale(counts_per_rev=8192, revolutions=4096)
    est = VelocityEstimator(scale, window=2, max_speed=1.0)
    est.update(0.0, scale.modulus - 2)
    assert est.update(0.01, 3) == pytest.approx(5 / 0.01 * scale.unit_per_count)
    assert est.implausible == 0
