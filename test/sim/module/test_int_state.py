"""The cycle keeps its state as ints; readers still see the same image and the IntFlag types.

``Xn1Ssi`` packs the process input with ``images.encode_input`` from ints and hands out
``CmpStatus`` / ``ModuleStatus`` / ``Diag`` from prebuilt tables (000 "Process input",
"Diagnostics"); these checks tie both to the decoded view on random cycles.
"""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from ssi_bridge.protocol.readout import LineReadout
from ssi_bridge.protocol.diagnostics import Diag
from ssi_bridge.protocol.images import (
    CmpStatus, ModuleStatus, ProcessInput, ProcessOutput, encode_input,
)
from ssi_bridge.protocol.registers import Reg
from ssi_bridge.sim.module.xn1ssi import Xn1Ssi


class ListReader:
    """Frames (data, trailer bit, start bit) in turn, the last one repeating."""

    def __init__(self, frames: list[tuple[int, int, int]]) -> None:
        self.frames = frames
        self.i = 0

    def read(self, t: float, n_bits: int, bit_rate_hz: float) -> LineReadout:
        data, trailer, start = self.frames[min(self.i, len(self.frames) - 1)]
        self.i += 1
        return LineReadout(t, n_bits, data & ((1 << n_bits) - 1), start_bit=start,
                           trailer_bit=trailer)


fields = st.tuples(st.integers(0, 0xFFFFFFFF), st.integers(0, 63), st.booleans(),
                   st.booleans(), st.booleans(), st.integers(0, 15), st.integers(0, 255),
                   st.sampled_from([0, 0x01, 0x02, 0x04, 0x08, 0x10, 0x80, 0x9F, 0x93]))


@settings(max_examples=200, deadline=None)
@given(values=fields)
def test_encode_input_is_process_input_encode(values: tuple) -> None:
    data, adr, abort, akn, accept, sts, cmp, byte7 = values
    image = ProcessInput(data, adr, abort, akn, accept, sts, CmpStatus(cmp),
                         ModuleStatus(byte7))
    assert encode_input(data, adr, abort, akn, accept, sts, cmp, byte7) == image.encode()


outputs = st.lists(st.builds(
    lambda data, rd, wr_adr, wr, ctl, stop: ProcessOutput(
        data, rd, wr_adr, wr, ctl & 0x1B, stop).encode(),
    st.sampled_from([0, 5, 100, 0xFFFFFFF0, 0x7FFFFFFF]), st.integers(0, 63),
    st.sampled_from([int(Reg.REG_CMP1), int(Reg.REG_CMP2), int(Reg.REG_LOWER_LIMIT),
                     int(Reg.REG_UPPER_LIMIT), int(Reg.REG_SSI_MASK), int(Reg.REG_OFFSET)]),
    st.booleans(), st.integers(0, 255), st.booleans()), min_size=1, max_size=40)
frames = st.lists(st.tuples(st.integers(0, 0x1FFFFFF), st.integers(0, 1), st.integers(0, 1)),
                  min_size=1, max_size=40)


@settings(max_examples=150, deadline=None)
@given(images=outputs, script=frames)
def test_image_status_and_diag_agree_every_cycle(images: list[bytes], script: list) -> None:
    module = Xn1Ssi(ListReader(script))
    for k, image in enumerate(images):
        module.set_process_output(image)
        module.cycle(k * 0.001)
        raw = module.process_input()
        status = module.status
        step = f"cycle {k}: out {image.hex(' ')} -> in {raw.hex(' ')}"
        assert raw == status.encode(), step
        assert ProcessInput.decode(raw) == status, step
        assert type(status.cmp) is CmpStatus and type(status.sts) is ModuleStatus, step
        assert type(module.diag) is Diag and int(module.diag) == raw[7] & 0x1F, step
        assert module.read_register(Reg.REG_DIAG1) == raw[7] & 0x1F, step
