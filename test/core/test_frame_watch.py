"""FrameWatch on real process input images (000 "Process input") and the CAM state field."""

from __future__ import annotations

from ssi_bridge.protocol.families import family_config
from ssi_bridge.sim.encoder.encoder import make_encoder
from ssi_bridge.sim.encoder.motion import Still
from ssi_bridge.protocol.images import encode_input
from ssi_bridge.protocol.registers import Reg
from ssi_bridge.core.frame_watch import CamSettings, FrameWatch


def _image(frame: int, adr: int = int(Reg.REG_SSI_FRAME), abort: bool = False) -> bytes:
    return encode_input(frame, adr, abort, False, False, 0, 0, 0)


def test_frame_from_reg_rd_data_is_checked() -> None:
    enc = make_encoder("TR_PARITY", Still(3.5 / 4096))
    frame = enc.frame_at(0.0).bits
    watch = FrameWatch(enc.config, 0x1A010200)
    before, after = watch.evaluate(_image(frame))
    assert watch.checked and not after.corrupt
    _, after = watch.evaluate(_image(frame ^ (1 << 5)))   # one flipped bit (001 §5.5.7)
    assert after.parity_error


def test_checksum_frame_cut_to_32_clocks_is_checked() -> None:
    # TR "Check sum" format (001 §5.2.4.2): 28 data + 15 checksum bits; the XN-1SSI clocks at
    # most 32 (000 Table 19), so REG_SSI_FRAME holds the data and the first 4 checksum bits
    enc = make_encoder("TR_CHECKSUM", Still(3.5 / 4096))
    frame = enc.frame_at(0.0).bits >> (43 - 32)
    watch = FrameWatch(enc.config, 0x20010420)     # SSI_FRAME_LEN 32, INVALID_BITS_LSB 4
    _, after = watch.evaluate(_image(frame))
    assert not after.corrupt
    _, after = watch.evaluate(_image(frame ^ 1))   # the last checksum bit read
    assert after.checksum_error and after.corrupt
    assert "checksum" in watch.failures.failed(0.0, after)


def test_no_check_without_the_frame_register() -> None:
    watch = FrameWatch(family_config("TR_PARITY"), 0x1A010200)
    assert watch.evaluate(_image(0x1234, adr=int(Reg.REG_SSI_POS))) is None
    assert watch.evaluate(_image(0, abort=True)) is None
    assert not watch.checked


def test_power_fail_bit_from_the_image() -> None:
    enc = make_encoder("SSI25_POWERFAIL", Still(0.5))
    enc.power_failure = True
    watch = FrameWatch(enc.config, 0x19010100)
    _, after = watch.evaluate(_image(enc.frame_at(0.0).bits))
    assert after.power_failure


def test_cam_state_of_table_42() -> None:
    # 000 Table 42 / docs/module.md: 0x01 inside CAM1 low (0x6B10) .. high (0x6B20) when
    # enabled (0x6B01), inverted by the polarity (0x6B02); Integer32 limits
    watch = FrameWatch(None, 0x19010000)
    assert watch.cam_state(150) == 0                     # not enabled
    watch.set_cam(CamSettings(100, 200, True, 0))
    assert (watch.cam_state(150), watch.cam_state(99), watch.cam_state(201)) == (1, 0, 0)
    watch.set_cam(CamSettings(0xFFFFFFF6, 10, True, 1))  # -10 .. 10, inverted
    assert (watch.cam_state(0xFFFFFFFB), watch.cam_state(11)) == (0, 1)
