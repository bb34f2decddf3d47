"""TR special bits (001 §5.5), cams/overspeed (§5.4), count direction, F/B input and preset."""

from __future__ import annotations

import pytest

from ssi_bridge.protocol.encoder_config import Direction, SpecialBit
from ssi_bridge.sim.encoder.encoder import make_encoder
from ssi_bridge.sim.encoder.motion import ConstantVelocity, Still, Waypoints
from ssi_bridge.exceptions import ConfigError

SPR = 4096


def _tr(motion, specials, **kw):
    return make_encoder("TR_PROGRAMMABLE", motion, special_bits=tuple(specials), **kw)


def _step(n: float) -> float:
    return (n + 0.5) / SPR


def test_going_up_down_standstill_50ms() -> None:
    """001 §5.5.3-5.5.5: going up/down, UP and moving; cleared after 50 ms without a step."""
    wp = Waypoints([(0.0, _step(100)), (0.01, _step(110)), (0.2, _step(110)),
                    (0.21, _step(100))])
    B = SpecialBit
    enc = _tr(wp, [B.GOING_UP, B.GOING_DOWN, B.UP, B.MOVING])
    enc.frame_at(0.0)
    assert enc.frame_at(0.005).flags == {B.GOING_UP, B.UP, B.MOVING}
    enc.frame_at(0.01)                                                    # last step (110)
    assert enc.frame_at(0.05).flags == {B.GOING_UP, B.UP, B.MOVING}      # < 50 ms since step
    assert enc.frame_at(0.061).flags == {B.UP}                            # >= 50 ms: stand-still
    assert enc.frame_at(0.205).flags == {B.GOING_DOWN, B.MOVING}         # UP cleared by down


def test_one_step_hysteresis() -> None:
    """001 §5.5.3: a one-step vibration is not signalled as movement (hysteresis one step)."""
    wp = Waypoints([(0.0, _step(100)), (0.001, _step(101)), (0.002, _step(100)),
                    (0.003, _step(101)), (0.004, _step(103))])
    enc = _tr(wp, [SpecialBit.MOVING])
    seen = [SpecialBit.MOVING in enc.frame_at(i * 1e-3).flags for i in range(5)]
    assert seen == [False, False, False, False, True]


def test_toggle_bit_changes_every_transmission() -> None:
    """001 §5.5.8: the toggle bit changes after each transmission, even with an error."""
    enc = _tr(Still(0.1), [SpecialBit.TOGGLE])
    levels = []
    for i in range(4):
        if i == 2:
            enc.set_error()
        levels.append(enc.frame_at(i * 1e-3).bits & 1)
    assert levels == [0, 1, 0, 1]


def test_dynamic_error_250hz_square_wave_and_encoder_error() -> None:
    """001 §5.5.6: healthy -> dynamic error is a 250 Hz square wave; error -> it stops."""
    enc = _tr(Still(0.1), [SpecialBit.ENCODER_ERROR, SpecialBit.DYNAMIC_ERROR])
    wave = [enc.frame_at(t * 1e-3).bits & 1 for t in (0.5, 1.5, 2.5, 3.5, 4.5, 5.5)]
    assert wave == [0, 0, 1, 1, 0, 0]                     # 2 ms high, 2 ms low
    enc.set_error()
    frames = [enc.frame_at(t * 1e-3).bits for t in (6.5, 8.5, 10.5)]
    assert {f & 1 for f in frames} == {frames[0] & 1}     # frozen level
    assert all((f >> 1) & 1 for f in frames)              # encoder error set


@pytest.mark.parametrize("bit, err, odd", [
    (SpecialBit.EVEN_PARITY, False, False), (SpecialBit.EVEN_PARITY, True, False),
    (SpecialBit.EVEN_ERROR_PARITY, False, False), (SpecialBit.EVEN_ERROR_PARITY, True, True),
])
def test_even_parity_and_error_parity(bit, err, odd) -> None:
    """001 §5.5.7: even parity over all previous bits; error parity inverted on an error."""
    for pos in (0.0, 0.3, 17.77, 1234.5):
        enc = _tr(Still(pos), [SpecialBit.ENCODER_ERROR, bit])
        if err:
            enc.set_error()
        ones = bin(enc.frame_at(0.0).bits).count("1")
        assert ones % 2 == (1 if odd else 0)


def test_inverted_parity_is_odd() -> None:
    """001 §5.5.7: selecting the inverted parity gives odd parity."""
    enc = _tr(Still(2.2), [SpecialBit.EVEN_PARITY], inverted_bits=frozenset({SpecialBit.EVEN_PARITY}))
    assert bin(enc.frame_at(0.0).bits).count("1") % 2 == 1


@pytest.mark.parametrize("value, on, off, active", [
    (100, 50, 150, True), (150, 50, 150, False), (49, 50, 150, False),
    (200, 150, 50, True), (10, 150, 50, True), (100, 150, 50, False),   # circulating cam
])
def test_cams(value, on, off, active) -> None:
    """001 §5.5.1: cam set on/above the switch-on point; on > off is a circulating cam."""
    enc = _tr(Still(_step(value)), [SpecialBit.CAM1], cams=((on, off),))
    assert (SpecialBit.CAM1 in enc.frame_at(0.0).flags) is active


def test_overspeed() -> None:
    """001 §5.4.2/§5.5.2: set when the speed exceeds the overspeed limit (1/min)."""
    slow = _tr(ConstantVelocity(1.0), [SpecialBit.OVERSPEED], overspeed_rpm=100)
    fast = _tr(ConstantVelocity(2.0), [SpecialBit.OVERSPEED], overspeed_rpm=100)
    assert not slow.frame_at(0.0).flags and fast.frame_at(0.0).flags == {SpecialBit.OVERSPEED}


@pytest.mark.parametrize("direction, fb, expect", [
    (Direction.INCREASING, False, 100), (Direction.DECREASING, False, SPR * 4096 - 101),
    (Direction.INCREASING, True, SPR * 4096 - 101), (Direction.DECREASING, True, 100),
])
def test_count_direction_and_fb_input(direction, fb, expect) -> None:
    """001 §5.1.1 count direction; §4.5 the F/B input inverts the set direction."""
    enc = _tr(Still(_step(100)), [], direction=direction)
    enc.fb_input = fb
    assert enc.frame_at(0.0).count == expect


def test_preset_shifts_zero_without_speed_jump() -> None:
    """001 §5.1.3/§5.1.4: preset adjusts the value; counting continues at the same speed."""
    enc = _tr(ConstantVelocity(1.0), [], preset_value=1000)
    before = enc.frame_at(0.5).count - enc.frame_at(0.4).count
    enc.apply_preset(0.5)
    assert enc.frame_at(0.5).count == 1000
    assert abs(enc.frame_at(0.6).count - enc.frame_at(0.5).count - before) <= 1  # floor
    with pytest.raises(ConfigError):
        enc.apply_preset(0.5, SPR * 4096)


def test_round_axis_wrap() -> None:
    """001 §5.1.2 / 004 §3.1 round axis: 100 steps over 12.5 revolutions, then zero again."""
    enc = make_encoder("TR_PROGRAMMABLE", Still(12.5 + 0.01), steps_per_rev=8,
                       revolutions_numerator=25, revolutions_divisor=2, data_bits=8)
    assert enc.config.range_steps == 100 and enc.frame_at(0.0).count == 0
