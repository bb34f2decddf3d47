"""Random process output images for many cycles keep the protocol invariants of 000 chapter 1
"Internal registers - read and write operations" and chapter 2 (process input/output)."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from ssi_bridge.exceptions import RegisterError
from ssi_bridge.protocol.readout import LineReadout
from ssi_bridge.protocol.images import CmpControl, CmpStatus, ModuleStatus, ProcessInput, ProcessOutput
from ssi_bridge.protocol.registers import REGISTERS, describe_refusal
from ssi_bridge.sim.module.xn1ssi import Xn1Ssi

WRITABLE = [r for r, i in REGISTERS.items() if i.writable]
CMP1_BITS = CmpStatus.STS_CMP1 | CmpStatus.FLAG_CMP1 | CmpStatus.REL_CMP1
CMP2_BITS = CmpStatus.STS_CMP2 | CmpStatus.FLAG_CMP2 | CmpStatus.REL_CMP2

# images biased towards interesting addresses: half of them pick a named register to write
def _write_image(data: int, adr: int, rd: int, ctl: int, stop: bool) -> bytes:
    cmp = CmpControl(ctl) & CmpControl(0x1B)
    return ProcessOutput(data, rd, adr, True, cmp, stop).encode()


SPECIAL_VALUES = [0x6C643230, 0x6C643438, 0x19010000, 0x99020000]
named_write = st.builds(
    _write_image,
    st.one_of(st.integers(0, 0xFFFFFFFF), st.sampled_from(SPECIAL_VALUES)),
    st.sampled_from([int(r) for r in WRITABLE]), st.integers(0, 63), st.integers(0, 255),
    st.booleans())
images = st.lists(st.one_of(st.binary(min_size=8, max_size=8), named_write),
                  min_size=1, max_size=60)
frames = st.lists(st.tuples(st.integers(0, 0xFFFFFFFF), st.integers(0, 1)), min_size=1, max_size=60)


class RandomReader:
    def __init__(self, frames: list[tuple[int, int]]) -> None:
        self.frames = frames
        self.i = 0

    def read(self, t: float, n_bits: int, bit_rate_hz: float) -> LineReadout:
        data, trailer = self.frames[self.i % len(self.frames)]
        self.i += 1
        return LineReadout(t, n_bits, data & ((1 << n_bits) - 1), trailer_bit=trailer)


@settings(max_examples=300, deadline=None)
@given(images=images, frames=frames)
def test_random_process_output_images_keep_the_invariants(images: list[bytes], frames) -> None:
    module = Xn1Ssi(RandomReader(frames))
    prev = ProcessInput.decode(module.process_input())
    for k, image in enumerate(images):
        out = ProcessOutput.decode(image)
        before = {r: module.read_register(r) for r in WRITABLE}
        module.set_process_output(image)
        module.cycle(k * 0.001)
        raw = module.process_input()
        assert len(raw) == 8
        now = ProcessInput.decode(raw)
        step = f"cycle {k}: out {image.hex(' ')} -> in {raw.hex(' ')}"
        # write handshake: AKN follows REG_WR, ACCEPT only with AKN, no write while AKN was 1
        assert now.reg_wr_akn == out.reg_wr, step
        assert not now.reg_wr_accept or now.reg_wr_akn, step
        if out.reg_wr and prev.reg_wr_akn:
            after = {r: module.read_register(r) for r in WRITABLE}
            assert after == before, f"{step}: write executed although REG_WR_AKN was 1"
        if out.reg_wr and not prev.reg_wr_akn and now.reg_wr_accept:
            assert describe_refusal(out.reg_wr_adr, write=True) is None, step
        # read: echo, abort <=> not readable, abort => zero data
        assert now.reg_rd_adr == out.reg_rd_adr, step
        assert now.reg_rd_abort == (describe_refusal(out.reg_rd_adr, write=False) is not None), step
        assert not now.reg_rd_abort or now.reg_rd_data == 0, step
        # control bits
        if CmpControl.EN_CMP1 not in out.cmp:
            assert not now.cmp & CMP1_BITS, step
        if CmpControl.EN_CMP2 not in out.cmp:
            assert not now.cmp & CMP2_BITS, step
        assert not (CmpStatus.STS_UP in now.cmp and CmpStatus.STS_DN in now.cmp), step
        stopped = out.stop or ModuleStatus.ERR_PARA in now.sts
        assert (ModuleStatus.STS_STOP in now.sts) == stopped, step
        assert ModuleStatus.ERR_PARA not in now.sts, f"{step}: process data cannot set ERR_PARA"
        assert int(module.diag) == int(now.sts) & 0x1F, step
        prev = now


@settings(max_examples=300, deadline=None)
@given(addr=st.integers(-5, 300), value=st.integers(-(2**33), 2**33))
def test_every_register_access_has_a_defined_result(addr: int, value: int) -> None:
    # any address 0..255 (and beyond), any value: a value or a RegisterError with a reason
    module = Xn1Ssi()
    try:
        module.write_register(addr, value)
    except RegisterError as err:
        assert err.reason and str(err).startswith("register 0x"), str(err)
    try:
        got = module.read_register(addr)
        assert 0 <= got <= 0xFFFFFFFF
    except RegisterError as err:
        assert err.reason in ("reserved", "out of range 0..63"), str(err)
    assert Xn1Ssi.validate_para1(value) is None or isinstance(Xn1Ssi.validate_para1(value), str)
