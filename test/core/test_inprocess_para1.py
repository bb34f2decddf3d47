"""REG_PARA1 changed at run time, in process: the bridge's scale follows the module.

000 Table 19: INVALID_BITS_LSB shifts REG_SSI_POS right, so dropping two LSB bits must keep
the published position (the scale follows); LD20 ("Resetting the register bank") restores the
binary default REG_PARA1, which misreads a Gray frame: the reply and the joint's status say
so (WARN), and the joint's own REG_PARA1 set again clears it. Moved from
test/ros/test_node_real_station.py (the simulated default's case; the separately started
station's stays there) and test/ros/test_node_live.py (docs/testing.md).
"""

from __future__ import annotations

import math
import time

from diagnostic_msgs.msg import DiagnosticStatus as D

from ssi_bridge.protocol.para1 import Para1
from ssi_bridge.protocol.registers import Reg

PARA1_TWO_INVALID_LSB = 0x19020200
PARA1_DEFAULT = 0x19010000  # 000 Table 19: 25-bit frame, 500 kbit/s, binary


def test_invalid_lsb_bits_keep_the_position_on_the_simulated_default(inprocess):
    b = inprocess({"joint1.motion.kind": "still", "joint1.motion.start": 0.3})
    b.run_until(lambda: len(b.joint_states()) > 20, 30.0, "joint_states")
    before = b.joint_states()[-1][2][0]
    assert math.isfinite(before)
    b.bridge.write_register(b.bridge.joint("joint1"), int(Reg.REG_PARA1), PARA1_TWO_INVALID_LSB)
    written = time.time()

    def after() -> list[float]:
        return [m[2][0] for m in b.joint_states() if m[0] > written + 0.3
                and math.isfinite(m[2][0])]

    b.run_until(lambda: bool(after()), 10.0, "joint_states after the write")
    # GENERIC: 8192 steps per revolution; two invalid LSB bits leave 2048 counts per turn
    lsb = Para1.decode(PARA1_TWO_INVALID_LSB).invalid_bits_lsb
    count = 2 * math.pi / (8192 / 2 ** lsb)
    assert abs(after()[0] - before) <= count, (
        f"position moved from {before} to {after()[0]} rad when REG_PARA1 dropped {lsb} LSB "
        f"bits (one count of the new resolution: {count:.6f} rad)")


def test_ld20_on_a_gray_encoder_says_the_default_does_not_fit_and_warns(inprocess):
    # shoulder as in config/ssi_bridge.yaml: AFM60 multiturn in Gray; LD20 restores the
    # binary default REG_PARA1, which misreads the Gray frame: say so, and WARN
    b = inprocess({"joints": ["shoulder"], "shoulder.family": "AFM60_MULTI",
                   "shoulder.code": "gray", "shoulder.steps_per_rev": 32768,
                   "shoulder.para1": 0x9E010300})
    message = b.bridge.reset_registers(b.bridge.joint("shoulder"), include_parameters=True)
    assert "does not fit" in message and "gray" in message, message
    assert b.para1["shoulder"] == PARA1_DEFAULT  # the parameter the node mirrors
    b.run_until(lambda: (st := b.status("shoulder")).level >= D.WARN
                and "does not fit" in st.message, 5.0,
                "shoulder WARN: REG_PARA1 does not fit the encoder")
    # the parameter set again (ros/node_params.py calls Bridge.change_para1)
    b.bridge.change_para1("shoulder", 0x9E010300, "parameter")
