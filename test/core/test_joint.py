"""The per-joint core, without ROS: what one sample of a cycle becomes (docs/node.md).

Each test feeds a :class:`Joint` process images as the XN-1SSI sends them (000 "Process
input": bytes 0-3 REG_RD_DATA, byte 4 REG_RD_ADR, byte 7 the status bits) with REG_SSI_POS
beside them, on a made-up wire time line of 1 ms cycles.
"""

from __future__ import annotations

import math

import pytest

from ssi_bridge.core.health import OK, STALE, WARN
from ssi_bridge.core.joint import Joint, joint_scale, spec_max_speed
from ssi_bridge.exceptions import ConfigError
from ssi_bridge.protocol.images import ModuleStatus, encode_input
from ssi_bridge.protocol.joint_encoder import joint_config
from ssi_bridge.protocol.registers import Reg
from ssi_bridge.protocol.settings import DEFAULT_PARA1, JointSettings

PERIOD = 0.001
#: REG_RD_ADR of the idle read: the raw SSI frame (000 chapter 1)
FRAME_REGISTER = int(Reg.REG_SSI_FRAME)


def _image(frame: int = 0, sts: int = 0, adr: int = FRAME_REGISTER) -> bytes:
    return encode_input(frame, adr, False, False, False, 0, 0, sts)


def _joint(**settings) -> Joint:
    values = dict(name="j", slot=1)
    values.update(settings)
    return Joint(JointSettings(**values), velocity_window=3, max_speed=0.0, stale_cycles=5)


def _feed(joint: Joint, n: int, pos_of=lambda k: 100 * k, sts: int = 0, start: int = 0,
          fresh: bool = True) -> list:
    outs = []
    for k in range(start, start + n):
        t = k * PERIOD
        latch = t if fresh else -1.0
        image = _image(sts=sts)
        joint.count(latch, image, pos_of(k), t)
        settled = ((k - 1) * PERIOD, 0.0 if fresh else 1.0) if k > 0 else None
        outs.append(joint.update(latch, image, pos_of(k), t, seq=k, settled=settled))
    return outs


def test_a_fresh_sample_is_reg_ssi_pos_in_radians_and_its_slope_the_velocity():
    joint = _joint()  # GENERIC: 8192 steps per revolution, REG_PARA1 default (25-bit frame)
    outs = _feed(joint, 10)
    assert outs[-1].position == pytest.approx(900 * 2 * math.pi / 8192)
    assert outs[-1].velocity == pytest.approx(100 / PERIOD * 2 * math.pi / 8192)


def test_invalid_lsb_bits_scale_reg_ssi_pos_by_their_power_of_two():
    """000 Table 19: INVALID_BITS_LSB shifts the frame right, so one count is 2^n steps."""
    joint = _joint()
    before = joint.scale.position(4096)
    joint.adopt_para1(DEFAULT_PARA1 | 0x0200, since=0.0)  # INVALID_BITS_LSB = 2
    assert joint.scale.position(1024) == pytest.approx(before)


def test_the_same_scale_for_a_real_and_a_simulated_joint():
    """One path: the scale depends on the parameters and REG_PARA1, nothing else."""
    settings = JointSettings(name="j", slot=1, family="AFM60_MULTI", steps_per_rev=32768,
                             code="gray", para1=0x9E020300)
    cfg = joint_config(settings)
    # 30 clocks, the 3 trailing error bits are INVALID_BITS_LSB: one count is one step
    assert joint_scale(settings, cfg, settings.para1).position(32768) == \
        pytest.approx(2 * math.pi)
    assert Joint(settings, velocity_window=3, max_speed=0.0, stale_cycles=5).scale.position(
        32768) == pytest.approx(2 * math.pi)


def test_a_linear_family_is_published_in_metres():
    joint = _joint(family="TTK70", para1=0x1A020200)
    assert joint.scale.linear
    outs = _feed(joint, 10, pos_of=lambda k: 10 * k)
    metres_per_count = joint.scale.position(1)
    assert 0 < metres_per_count < 1e-3
    assert outs[-1].velocity == pytest.approx(10 / PERIOD * metres_per_count)


def test_a_sample_latched_while_reg_para1_changes_is_unknown():
    joint = _joint()
    _feed(joint, 5)
    joint.para1_changing()
    out = _feed(joint, 1, start=5)[0]
    assert math.isnan(out.position) and math.isnan(out.velocity)
    joint.adopt_para1(joint.para1, since=5.5 * PERIOD)
    assert math.isfinite(_feed(joint, 1, start=6)[0].position)


@pytest.mark.parametrize("bit", [ModuleStatus.ERR_SSI, ModuleStatus.ERR_PARA,
                                 ModuleStatus.STS_STOP])
def test_while_the_module_does_not_measure_the_speed_is_unknown(bit):
    """000 "Error detection": REG_SSI_POS is frozen; the position stays, the speed is NaN."""
    joint = _joint()
    _feed(joint, 5)
    out = _feed(joint, 1, pos_of=lambda k: 400, sts=int(bit), start=5)[0]
    assert out.position == pytest.approx(400 * 2 * math.pi / 8192)
    assert math.isnan(out.velocity)


def test_stale_for_stale_cycles_makes_the_speed_unknown_and_the_level_stale():
    joint = _joint()
    _feed(joint, 5)
    outs = _feed(joint, 6, pos_of=lambda k: 400, start=5, fresh=False)
    assert math.isfinite(outs[2].velocity)  # not yet stale_cycles (5) without a fresh one
    assert math.isnan(outs[-1].velocity)
    _feed(joint, 150, pos_of=lambda k: 400, start=11, fresh=False)  # past the 0.1 s debounce
    assert joint.health.level == STALE


def test_a_frame_that_fails_its_parity_keeps_the_last_good_position():
    """001 5.5.7 even parity: a frame whose parity bit does not match is not believed."""
    joint = _joint(family="TR_PARITY", para1=0x1A020000)  # 24 data + error + parity bits
    cfg = joint.config
    assert cfg is not None and joint.para1_note == ""
    good = _feed(joint, 3)[-1]
    bad_frame = 0b100  # data 1 (one "1"), error 0, parity 0: even parity needs 1
    t = 3 * PERIOD
    image = _image(frame=bad_frame)
    joint.count(t, image, 9999, t)
    out = joint.update(t, image, 9999, t, seq=3, settled=None)
    if joint.counters.frame is not None and joint.counters.frame.corrupt:
        assert out.position == good.position
        assert joint.counters.frame_errors == 1
        assert any(not ok for ok, _ in out.events)
    else:
        pytest.fail(f"the frame 0b1 passed the {cfg.name} checks: {joint.counters.frame}")


def test_a_reg_para1_that_does_not_fit_the_encoder_is_a_warning():
    joint = _joint(para1=0x1A020000)  # 26 clocks for the 25-bit GENERIC frame
    assert "SSI_FRAME_LEN 26" in joint.para1_note
    _feed(joint, 20)
    assert joint.health.level == OK and joint.level == WARN


def test_max_speed_minus_one_is_the_family_limit_and_other_negatives_are_refused():
    joint = _joint(family="TR_PARITY")
    joint.set_max_speed(-1)
    assert joint.max_speed == spec_max_speed("TR_PARITY") > 0
    with pytest.raises(ConfigError, match="max_speed"):
        joint.set_max_speed(-2)
