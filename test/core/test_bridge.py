"""The facade the services call (core/bridge.py), against a register bank kept in a dict.

The bank stands for the module's registers as the master's handshake reaches them; what is
checked is the bridge's own arithmetic and its one REG_PARA1 path (000 "Offset function",
"Resetting the register bank", Table 19), not the handshake (test/client covers that).
"""

from __future__ import annotations

import math

import pytest

from ssi_bridge.core.bridge import SF_LD20, SF_LD48, Bridge
from ssi_bridge.core.joint import Joint
from ssi_bridge.exceptions import ConfigError, HandshakeTimeout
from ssi_bridge.protocol.registers import Reg
from ssi_bridge.protocol.settings import DEFAULT_PARA1, JointSettings


class Bank:
    """Registers of one slot; REG_SSI_POS = encoder - REG_OFFSET (000 "Offset function")."""

    def __init__(self, encoder: int = 5000) -> None:
        self.encoder = encoder
        self.regs = {int(Reg.REG_OFFSET): 0, int(Reg.REG_PARA1): DEFAULT_PARA1}
        self.fail_writes = False
        self.written: list[tuple[int, int]] = []
        #: the gateway's heartbeat is current (BridgeClient.gateway_alive)
        self.gateway_alive = True
        #: SDO objects read (index, slot) and their values (read_object)
        self.objects_read: list[tuple[int, int]] = []
        self.objects: dict[int, int] = {}

    def read_object(self, index: int, slot: int) -> int:
        self.objects_read.append((index, slot))
        return self.objects.get(index, 0)

    def read_register(self, slot: int, address: int) -> int:
        if address == Reg.REG_SSI_POS:
            return (self.encoder - self.regs[int(Reg.REG_OFFSET)]) & 0xFFFF_FFFF
        return self.regs.get(address, 0)

    def write_register(self, slot: int, address: int, value: int) -> None:
        if self.fail_writes:
            raise HandshakeTimeout("slot 1: register write not acknowledged")
        self.written.append((address, value))
        if address == Reg.REG_SF and value == SF_LD20:
            self.regs[int(Reg.REG_PARA1)] = 0x19010000  # the factory REG_PARA1
        else:
            self.regs[address] = value


@pytest.fixture
def setup():
    bank = Bank()
    joints = {"a": Joint(JointSettings(name="a", slot=1), velocity_window=3, max_speed=0.0,
                         stale_cycles=5)}
    mirrored: list[tuple[str, int]] = []
    bridge = Bridge(joints, lambda name: bank, lambda j, v: mirrored.append((j, v)))
    return bridge, bank, mirrored


def test_an_empty_joint_name_is_the_first_and_an_unknown_one_is_named(setup):
    bridge, _, _ = setup
    assert bridge.joint("").name == "a"
    with pytest.raises(ConfigError, match="unknown joint 'b'; configured joints: a"):
        bridge.joint("b")


def test_addresses_outside_the_bank_are_refused(setup):
    bridge, _, _ = setup
    with pytest.raises(ConfigError, match="out of range 0..63"):
        bridge.read_register(bridge.joint("a"), 64)


def test_a_preset_writes_the_offset_that_makes_reg_ssi_pos_read_the_target(setup):
    bridge, bank, _ = setup
    joint = bridge.joint("a")
    target = joint.scale.position(1234)
    offset, after, text = bridge.set_preset(joint, target)
    assert offset == 5000 - 1234
    assert after == pytest.approx(target)
    assert "REG_OFFSET <- 3766" in text


def test_a_preset_outside_integer32_is_refused(setup):
    bridge, _, _ = setup
    with pytest.raises(ConfigError, match="Integer32"):
        bridge.set_preset(bridge.joint("a"), 1e12)
    with pytest.raises(ConfigError, match="not a finite number"):
        bridge.set_preset(bridge.joint("a"), math.nan)


def test_an_invalid_reg_para1_is_refused_before_the_bus_with_the_modules_rule(setup):
    bridge, bank, _ = setup
    with pytest.raises(ConfigError, match="ERR_PARA"):
        bridge.write_register(bridge.joint("a"), int(Reg.REG_PARA1), 0x00020000)  # 0 bits
    assert bank.written == []


def test_a_reg_para1_write_moves_the_scale_and_the_parameter(setup):
    bridge, bank, mirrored = setup
    joint = bridge.joint("a")
    before = joint.scale.position(4096)
    bridge.write_register(joint, int(Reg.REG_PARA1), DEFAULT_PARA1 | 0x0200)
    assert bank.regs[int(Reg.REG_PARA1)] == DEFAULT_PARA1 | 0x0200
    assert joint.para1 == DEFAULT_PARA1 | 0x0200 and mirrored == [("a", joint.para1)]
    assert joint.scale.position(1024) == pytest.approx(before)


def test_a_failed_reg_para1_write_keeps_the_old_value_everywhere(setup):
    bridge, bank, mirrored = setup
    joint = bridge.joint("a")
    bank.fail_writes = True
    with pytest.raises(HandshakeTimeout):
        bridge.change_para1("a", DEFAULT_PARA1 | 0x0200, "parameter")
    assert joint.para1 == DEFAULT_PARA1 and mirrored == [("a", DEFAULT_PARA1)]
    assert joint.para1_since < math.inf  # samples are believed again


def test_ld20_adopts_the_reg_para1_the_module_now_holds(setup):
    bridge, bank, mirrored = setup
    joint = bridge.joint("a")
    text = bridge.reset_registers(joint, include_parameters=True)
    assert joint.para1 == 0x19010000 and mirrored[-1] == ("a", 0x19010000)
    assert "0x19020000 -> 0x19010000" in text


def test_ld48_leaves_reg_para1(setup):
    bridge, bank, mirrored = setup
    joint = bridge.joint("a")
    bridge.reset_registers(joint, include_parameters=False)
    assert bank.written == [(int(Reg.REG_SF), SF_LD48)]
    assert joint.para1 == DEFAULT_PARA1 and mirrored == []


def test_fault_injection_is_refused_on_real_hardware(setup):
    bridge, _, _ = setup
    with pytest.raises(ConfigError, match="simulation.enabled:=true"):
        bridge.inject_fault(bridge.joint("a"), 1, 0.0, 0.0)


def test_cam_objects_are_read_each_round_but_not_from_a_silent_gateway(setup):
    """The CAM objects (0x6B10/0x6B20/0x6B01/0x6B02, 000 Tables 43-48) are read over SDO each
    diagnostics round; a gateway without heartbeat is not asked (each transfer would wait
    out bus.sdo_timeout and hold up the diagnostics of every station), and the joint is
    named as not read."""
    bridge, bank, _ = setup
    bank.objects[0x6B01] = 1  # CAM enable: the limits are read too (Table 42)
    assert bridge.refresh_cams() == []
    asked = {index for index, _ in bank.objects_read}
    assert asked == {0x6B10, 0x6B20, 0x6B01, 0x6B02}, asked
    bank.objects_read.clear()
    bank.gateway_alive = False
    failed = bridge.refresh_cams()
    assert [name for name, _ in failed] == ["a"] and "silent" in str(failed[0][1])
    assert bank.objects_read == [], "a silent gateway is not asked"
