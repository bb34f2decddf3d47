"""``<joint>.max_speed: -1`` is a physical limit for every family, never off (docs/node.md).

No manual states a shaft speed: 004 (SICK) and 003 (EL500x notes) give none, and 001 (TR)
only the range of its speed monitor's threshold, "The maximum speed must be between 10 and
6000 min-1" (001 §5.4.2), which a faster shaft exceeds and reports with the overspeed special
bit (§5.5.2): so a TR shaft can turn faster than 6000 1/min, and every family takes the
documented default: 12000 1/min rotary (GENERIC and TR included), 10 m/s linear. A jump no
shaft can make is then flagged without any setting, as #23 found it was not for GENERIC (a
TPDO of the wrong length published as -1 098 066 rad).
"""

from __future__ import annotations

import math

import pytest

from ssi_bridge.core.joint import Joint, spec_max_speed
from ssi_bridge.protocol.encoder_config import SpecialBit
from ssi_bridge.protocol.families import FAMILIES, family_max_speed
from ssi_bridge.protocol.images import encode_input
from ssi_bridge.protocol.registers import Reg
from ssi_bridge.protocol.settings import JointSettings
from ssi_bridge.sim.encoder.encoder import make_encoder
from ssi_bridge.sim.encoder.motion import ConstantVelocity

OVERSPEED = SpecialBit.OVERSPEED

RPM = 2 * math.pi / 60                      # rad/s per 1/min
ROTARY_DEFAULT = 12000 * RPM                # docs/node.md: 1256.6 rad/s
LINEAR_DEFAULT = 10.0                       # docs/node.md: m/s
EXPECTED = {family: ROTARY_DEFAULT for family in FAMILIES}
EXPECTED.update(TTK70=LINEAR_DEFAULT, KH53=LINEAR_DEFAULT)
PERIOD = 0.002                              # 500 Hz
IMAGE = encode_input(0, int(Reg.REG_SSI_FRAME), False, False, False, 0, 0, 0)


@pytest.mark.parametrize("family", sorted(FAMILIES))
def test_every_family_has_a_physical_limit_by_default(family: str) -> None:
    assert spec_max_speed(family) == pytest.approx(EXPECTED[family])
    spec = family_max_speed(family)
    assert spec.linear == (family in ("TTK70", "KH53"))
    # the TR text names 001 §5.4.2 as what it is, a monitor's threshold
    assert ("001 §5.4.2" in spec.source) == family.startswith("TR_"), spec.source
    assert ("threshold" in spec.source) == family.startswith("TR_"), spec.source
    joint = Joint(JointSettings(name="j", slot=1, family=family), velocity_window=3,
                  max_speed=-1.0, stale_cycles=5)
    assert joint.max_speed == pytest.approx(EXPECTED[family]) and joint.max_speed > 0
    assert joint.velocity.max_speed == joint.max_speed


def test_an_unknown_family_or_a_linear_joint_gets_the_default_of_its_kind() -> None:
    assert spec_max_speed("NO_SUCH_FAMILY") == pytest.approx(ROTARY_DEFAULT)
    joint = Joint(JointSettings(name="j", slot=1, family="NO_SUCH_FAMILY", measuring_step=1e-5),
                  velocity_window=3, max_speed=-1.0, stale_cycles=5)
    assert joint.config is None and joint.scale.linear
    assert joint.max_speed == LINEAR_DEFAULT


def _run(joint: Joint, positions: list[int], start: int = 0) -> list[float]:
    velocities = []
    for k, pos in enumerate(positions, start):
        t = k * PERIOD
        joint.count(t, IMAGE, pos, t)
        settled = ((k - 1) * PERIOD, 0.0) if k else None
        velocities.append(joint.update(t, IMAGE, pos, t, seq=k, settled=settled).velocity)
    return velocities


def test_generic_flags_a_jump_no_shaft_makes_without_any_setting() -> None:
    # GENERIC (8192 steps per revolution) at 500 Hz, max_speed left at its default -1
    joint = Joint(JointSettings(name="j", slot=1), velocity_window=3, max_speed=-1.0,
                  stale_cycles=5)
    fast_but_real = [k * 8192 * 100 * PERIOD for k in range(20)]   # 6000 1/min: 100 rev/s
    out = _run(joint, [int(p) for p in fast_but_real])
    assert joint.counters.implausible == 0
    assert out[-1] == pytest.approx(100 * 2 * math.pi, rel=1e-3)
    # a misread multiturn bit: 1024 revolutions in one cycle (REG_SSI_POS 2**23 higher)
    glitch = int(fast_but_real[-1]) + (1 << 23)
    out = _run(joint, [glitch], start=len(fast_but_real))
    assert joint.counters.implausible == 1 and math.isnan(out[-1])


def test_a_tr_shaft_above_its_overspeed_threshold_is_motion_not_a_bit_error() -> None:
    # 001 §5.4.2: the speed monitor's threshold is at most 6000 1/min; §5.5.2: the overspeed
    # bit is set when the shaft exceeds it. So 7000 1/min is a speed the encoder itself
    # reports as real: the simulated TR encoder sets its overspeed bit there ...
    rps = 7000 / 60
    enc = make_encoder("TR_PROGRAMMABLE", ConstantVelocity(rps), special_bits=(OVERSPEED,))
    assert enc.config.overspeed_rpm == 6000
    enc.frame_at(0.0)
    assert enc.frame_at(0.01).bits & 1, "no overspeed bit at 7000 1/min"
    # ... and the node takes its steps as motion (max_speed -1), not as implausible jumps
    joint = Joint(JointSettings(name="j", slot=1, family="TR_PROGRAMMABLE"), velocity_window=3,
                  max_speed=-1.0, stale_cycles=5)
    counts_per_rev = 2 * math.pi / joint.scale.unit_per_count
    out = _run(joint, [int(k * counts_per_rev * rps * PERIOD) for k in range(20)])
    assert joint.counters.implausible == 0
    assert out[-1] == pytest.approx(rps * 2 * math.pi, rel=1e-2)


def test_zero_still_switches_the_check_off() -> None:
    joint = Joint(JointSettings(name="j", slot=1), velocity_window=3, max_speed=0.0,
                  stale_cycles=5)
    _run(joint, [0, 0, 1 << 23, 0])
    assert joint.counters.implausible == 0
    joint.set_max_speed(-1)
    assert joint.max_speed == pytest.approx(ROTARY_DEFAULT)


def test_the_parameter_description_says_what_minus_one_means() -> None:
    from ssi_bridge.ros.param_table import JOINT_PARAMETERS  # the declared descriptor
    default, descriptor = JOINT_PARAMETERS["max_speed"]
    text = descriptor.description
    assert default == -1.0
    for words in ("6000 1/min", "001 §5.4.2", "threshold", "GENERIC", "TR", "12000 1/min",
                  "10 m/s", "0: off"):
        assert words in text, f"{words!r} not in the max_speed description: {text}"
    assert "off where the family states none" not in text
