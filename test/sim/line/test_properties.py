"""Property tests: encode -> line -> decode returns the position and flags exactly (no fault)."""

from __future__ import annotations

from hypothesis import given, settings, strategies as st

from ssi_bridge.protocol.codes import Code
from ssi_bridge.protocol.encoder_config import ERROR_BITS, Negative, SpecialBit
from ssi_bridge.protocol.families import FAMILIES
from ssi_bridge.sim.encoder.encoder import make_encoder
from ssi_bridge.protocol.layout import decode_area, split
from ssi_bridge.sim.encoder.motion import Still
from ssi_bridge.protocol.decode import MasterStatus, check_readout, decode_frame
from ssi_bridge.sim.line.line import LineConfig, SsiLine

FAMILY_NAMES = sorted(n for n in FAMILIES if n not in ("KH53",))
ERROR_CAPABLE = {SpecialBit.ERROR, SpecialBit.ERRDIG, SpecialBit.ERRSI, SpecialBit.ERRSYNC,
                 SpecialBit.ERR_POSITION, SpecialBit.ERR_SENDER, SpecialBit.ERR_DISTANCE,
                 SpecialBit.ERR_TEMPERATURE}


def _roundtrip(enc, t: float, rate: float) -> tuple[int, dict]:
    line = SsiLine(enc, LineConfig(check_cable_table=False))
    r = line.read(t, enc.frame_bits, rate)
    assert check_readout(r) == MasterStatus.OK, r
    area, levels = split(enc.config, r.data)
    return decode_area(enc.config, area), levels


@settings(max_examples=300, deadline=None)
@given(family=st.sampled_from(FAMILY_NAMES), frac=st.floats(0.0, 0.999999),
       err=st.booleans(), rate=st.sampled_from([100e3, 500e3, 1e6, 2e6]))
def test_family_roundtrip(family: str, frac: float, err: bool, rate: float) -> None:
    """004 §2.2/§3: any family, any position: the decoded value and error bits are exact."""
    enc = make_encoder(family)
    cfg = enc.config
    count = int(frac * cfg.range_steps)
    enc.motion = Still((count + 0.5) / cfg.steps_per_unit)
    errs = {b for b in cfg.special_bits if b in ERROR_CAPABLE}
    if err and errs and cfg.error_output.value == "flags":
        enc.set_error(bits=errs)
    value, levels = _roundtrip(enc, 0.0, rate)
    assert value == count
    # status bits that are not error bits (parity, 001 §5.5.7; PowerFail, 003) follow the data
    assert ({b for b, lvl in levels.items() if lvl and b in ERROR_BITS}
            == (errs if enc.errors else set()))


@settings(max_examples=300, deadline=None)
@given(code=st.sampled_from([Code.BINARY, Code.GRAY, Code.BCD]), spr=st.integers(2, 5000),
       revs=st.integers(1, 64), frac=st.floats(0.0, 0.999999),
       neg=st.sampled_from(list(Negative)), origin_frac=st.sampled_from([0.0, 0.5]),
       extra_bits=st.integers(0, 6), fb=st.booleans())
def test_programmable_roundtrip(code, spr, revs, frac, neg, origin_frac, extra_bits, fb) -> None:
    """001 §5: scaling, code, data bits, negative values: the wire value equals the count.

    The codes of 001 §5.2.2 (binary, Gray, BCD: no Gray-excess on a TR encoder), and a plain
    frame of 8..36 bits (001 §5.2.4.1): at least 8 data bits, the probe at 36.
    """
    total = spr * revs
    origin = -int(total * origin_frac)
    probe = make_encoder("TR_PROGRAMMABLE", steps_per_rev=spr, revolutions_numerator=revs,
                         origin=origin, negative=neg, code=code, data_bits=36)
    data_bits = max(8, probe.config.value_bits + extra_bits)
    enc = make_encoder("TR_PROGRAMMABLE", steps_per_rev=spr, revolutions_numerator=revs,
                       origin=origin, negative=neg, code=code, data_bits=data_bits)
    enc.fb_input = fb
    value = origin + int(frac * total)
    sign = -1 if fb else 1
    enc.motion = Still(sign * (value + 0.5) / enc.config.steps_per_unit)
    got, _ = _roundtrip(enc, 0.0, 1e6)
    assert got == value


@settings(max_examples=200, deadline=None)
@given(count=st.integers(0, (1 << 25) - 1), gray=st.booleans(), lsb=st.integers(0, 3))
def test_generic_master_decode(count: int, gray: bool, lsb: int) -> None:
    """000 REG_PARA1: the module decode of the default 25-bit frame returns the count."""
    enc = make_encoder("GENERIC", Still((count + 0.5) / 8192),
                       code=Code.GRAY if gray else Code.BINARY)
    line = SsiLine(enc, LineConfig(check_cable_table=False))
    r = line.read(0.0, 25, 500e3)
    assert decode_frame(r.data, 25, gray=gray) == count
    assert decode_frame(r.data, 25, gray=gray, invalid_lsb=lsb) == count >> lsb
