"""The truth oracle (test/support/truth.py) against the simulated station's own model.

Samples made by the simulator itself (the same encoder, SSI line and XN-1SSI module the
station builds from the node's parameters, cycled at known wire times, through the node's
counts -> units scale) are exact: residual 0. A sample latched 2 s before its stamp is off by
2 s of motion, and the rule (1 count + max speed x latch bound) catches it. Velocities from
the node's own estimator (core/velocity.py) hold docs/node.md's bound ("Velocity"). Families
and REG_PARA1 values as in config/ssi_bridge.yaml (000 Table 19 frame layouts).
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest

from ssi_bridge.core.joint import joint_scale
from ssi_bridge.core.velocity import VelocityEstimator
from ssi_bridge.protocol.joint_encoder import joint_config
from ssi_bridge.protocol.registers import Reg
from ssi_bridge.sim.gateway.station import SimStation
from support.truth import Sample, TruthOracle, joints_of, samples_from_joint_states

EPOCH = 1_795_000_000.25  # a wire time (s): the station's motion epoch
RATE = 200.0  # SYNCs per second
ROTARY = {"family": "AFM60_MULTI", "code": "gray", "steps_per_rev": 32768,
          "para1": 0x9E020300}
LINEAR = {"family": "TTK70", "para1": 0x1A020200}
GENERIC = {"family": "GENERIC"}
CONSTANT = {"motion.kind": "constant", "motion.velocity": 0.25, "motion.start": 1.0}
SINE = {"motion.kind": "sine", "motion.amplitude": 0.25, "motion.frequency": 0.5,
        "motion.start": 1.0}
LINEAR_CONSTANT = {"motion.kind": "constant", "motion.velocity": 0.01}


def params(joint: dict, **extra: object) -> dict:
    return {"joints": ["j"], **{f"j.{k}": v for k, v in joint.items()}, **extra}


def station_samples(values: dict, times: list[float], *, offset: int = 0,
                    latched_early: float = 0.0) -> list[Sample]:
    """What the node publishes for latches at ``times`` (wire s), made by the simulator:
    the station's own module cycled at each (``latched_early`` s before the stamp), REG_SSI_POS
    through the node's scale, velocity from the node's estimator."""
    (joint,) = joints_of(values)
    module = SimStation((joint,)).modules[0]
    module.write_para1(joint.para1)
    module.write_register(Reg.REG_OFFSET, offset & 0xFFFF_FFFF)
    scale = joint_scale(joint, joint_config(joint), joint.para1)
    estimator = VelocityEstimator(scale, 5)
    out = []
    for t in times:
        module.cycle(t - latched_early - EPOCH)
        velocity = estimator.update(t, module.ssi_pos)
        out.append(Sample(t, "j", scale.position(module.ssi_pos), velocity))
    return out


def cycles(n: int, start: float = 10.0, rate: float = RATE) -> list[float]:
    # on the 150 us formation grid of ATM60 and the 125 us of AHM36 too: the value the
    # encoder formed is the shaft's at the stamp itself
    step = round(1.0 / rate / 750e-6) * 750e-6
    return [EPOCH + start + k * step for k in range(n)]


@pytest.mark.parametrize("joint, motion", [
    (ROTARY, CONSTANT), (ROTARY, SINE), (LINEAR, LINEAR_CONSTANT), (GENERIC, SINE),
    ({**ROTARY, "direction": -1}, SINE), ({**LINEAR, "direction": -1}, LINEAR_CONSTANT),
])
def test_samples_of_the_simulator_itself_are_exact(joint: dict, motion: dict) -> None:
    values = params({**joint, **motion})
    oracle = TruthOracle.from_params(values, EPOCH)
    samples = station_samples(values, cycles(400))
    for s in samples:
        assert oracle.residual("j", s.stamp, s.position) == pytest.approx(0.0, abs=1e-6)
    report = oracle.check(samples, latch_bound_s=0.0)
    assert report.ok, report.summary()
    assert report.checked == 400
    assert report.velocities_checked >= 390
    assert report.worst_residual_counts == pytest.approx(0.0, abs=1e-6)


def test_a_preset_offset_is_part_of_the_truth() -> None:
    values = params({**ROTARY, **CONSTANT})
    samples = station_samples(values, cycles(50), offset=123_456)
    assert TruthOracle.from_params(values, EPOCH, offsets={"j": 123_456}).check(samples).ok
    # the same samples against a station without the preset: off by exactly the offset
    plain = TruthOracle.from_params(values, EPOCH)
    assert plain.residual("j", samples[0].stamp, samples[0].position) == pytest.approx(
        -123_456, abs=1e-6)


@pytest.mark.parametrize("joint, motion", [(ROTARY, CONSTANT), (LINEAR, LINEAR_CONSTANT),
                                           ({**ROTARY, "direction": -1}, CONSTANT)])
def test_a_sample_latched_2_s_before_its_stamp_is_off_by_2_s_of_motion(joint: dict,
                                                                     motion: dict) -> None:
    values = params({**joint, **motion})
    oracle = TruthOracle.from_params(values, EPOCH)
    late = station_samples(values, cycles(20), latched_early=2.0)
    expected = -2.0 * oracle.max_speed("j") * oracle.counts_per_unit("j")
    sign = math.copysign(1.0, oracle.velocity("j", late[0].stamp))
    for s in late:
        assert oracle.residual("j", s.stamp, s.position) == pytest.approx(sign * expected,
                                                                          abs=1.0)
    report = oracle.check(late, latch_bound_s=0.010)
    assert [v.kind for v in report.violations] == ["position"] * 20
    assert report.worst_residual_counts == pytest.approx(abs(expected), abs=1.0)


def test_the_latch_bound_widens_the_rule_by_max_speed_times_it() -> None:
    values = params({**ROTARY, **CONSTANT})
    oracle = TruthOracle.from_params(values, EPOCH)
    late = station_samples(values, cycles(20), latched_early=0.004)
    per_ms = oracle.max_speed("j") * oracle.counts_per_unit("j") / 1000.0
    assert not oracle.check(late, latch_bound_s=0.005).violations
    assert len(oracle.check(late, latch_bound_s=0.003).violations) == 20
    assert oracle.position_bound("j", 0.005) == pytest.approx(1 + 5 * per_ms)


def test_a_velocity_off_its_bound_is_caught_and_nan_is_never_wrong() -> None:
    values = params({**ROTARY, **SINE})
    oracle = TruthOracle.from_params(values, EPOCH)
    samples = station_samples(values, cycles(100))
    true_peak = oracle.max_speed("j")
    bad = [Sample(s.stamp, s.joint, s.position, 3.0 * true_peak) if k == 60 else s
           for k, s in enumerate(samples)]
    report = oracle.check(bad)
    assert [(v.kind, v.stamp) for v in report.violations] == [("velocity", samples[60].stamp)]
    unknown = [Sample(s.stamp, s.joint, s.position, math.nan) if k == 60 else s
               for k, s in enumerate(samples)]
    assert oracle.check(unknown).ok


def test_the_truth_is_wrapped_at_the_multiturn_range() -> None:
    # GENERIC: 8192 steps x 4096 turns; a shaft crossing the wrap at 4096 rev
    values = params({**GENERIC, "motion.kind": "constant", "motion.velocity": 2.0,
                     "motion.start": 4096.0 - 20.0})
    oracle = TruthOracle.from_params(values, EPOCH)
    samples = station_samples(values, cycles(400))  # 2 s at 2 rev/s: through the wrap
    positions = [s.position for s in samples]
    assert max(positions) - min(positions) > 6.0  # the published value wrapped
    assert oracle.check(samples).ok
    full = oracle.joints["j"].scale.modulus
    shifted = samples[0].position + full * abs(oracle.joints["j"].scale.unit_per_count)
    assert oracle.residual("j", samples[0].stamp, shifted) == pytest.approx(0.0, abs=1e-6)


def test_the_true_velocity_is_the_slope_of_the_true_position() -> None:
    values = params({**ROTARY, **SINE, "direction": -1})
    oracle = TruthOracle.from_params(values, EPOCH)
    t, h = EPOCH + 3.3, 0.01
    slope = (oracle.position("j", t + h) - oracle.position("j", t - h)) / (2 * h)
    assert oracle.velocity("j", t) == pytest.approx(slope, rel=2e-3)
    assert oracle.max_speed("j") == pytest.approx(0.25 * 2 * math.pi * 0.5 * 2 * math.pi)


def test_two_stations_each_with_its_epoch() -> None:
    values = {"joints": ["a", "b"], "stations": [1, 2], "a.station": 1, "b.station": 2,
              "a.family": "GENERIC", "b.family": "GENERIC", "b.motion.velocity": 0.5}
    oracle = TruthOracle.from_params(values, {1: EPOCH, 2: EPOCH + 100.0})
    assert [(j.station, j.slot) for j in joints_of(values)] == [(1, 1), (2, 1)]
    # b's station started 100 s later: at a wire time, its shaft has moved 100 s less
    t = EPOCH + 150.0
    assert oracle.position("b", t) == pytest.approx(
        oracle.position("b", t + 100.0) - 100.0 * oracle.velocity("b", t), abs=1e-3)
    with pytest.raises(KeyError):
        TruthOracle.from_params(values, {1: EPOCH})
    with pytest.raises(KeyError):
        oracle.position("c", t)


def test_nested_params_as_a_params_file_gives_them() -> None:
    nested = {"joints": ["j"], "velocity_window": 7,
              "j": {"family": "TTK70", "para1": 0x1A020200, "motion": {"velocity": 0.02}}}
    oracle = TruthOracle.from_params(nested, EPOCH)
    assert oracle.velocity_window == 7
    assert oracle.max_speed("j") == pytest.approx(0.02)
    assert oracle.counts_per_unit("j") == pytest.approx(1e6)


def test_joint_states_become_samples_without_ros() -> None:
    msg = SimpleNamespace(header=SimpleNamespace(stamp=SimpleNamespace(sec=12, nanosec=5)),
                          name=["a", "b"], position=[1.0, 2.0], velocity=[0.5])
    got = samples_from_joint_states([msg, (13.5, ["a"], [1.5], [0.25])])
    assert got[0] == Sample(12.000000005, "a", 1.0, 0.5)
    assert got[1].joint == "b" and math.isnan(got[1].velocity)
    assert got[2] == Sample(13.5, "a", 1.5, 0.25)
