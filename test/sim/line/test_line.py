"""The SSI line: clock burst, pause-1 bit, monoflop, faults and their detection."""

from __future__ import annotations

import pytest

from ssi_bridge.protocol.encoder_config import SpecialBit, SsiMode
from ssi_bridge.sim.encoder.encoder import make_encoder
from ssi_bridge.sim.encoder.motion import ConstantVelocity, Still
from ssi_bridge.protocol.decode import MasterStatus, check_readout, decode_frame
from ssi_bridge.sim.line.line import LineConfig, SsiLine
from ssi_bridge.sim.line.multi import MultipleTransmission

RATE = 250e3          # below the 004 §2.7 recommendation for a 10 m cable
POS = 5 + 1234.5 / 8192


def _line(family: str = "GENERIC", pos: float = POS, **cfg) -> SsiLine:
    return SsiLine(make_encoder(family, Still(pos)), LineConfig(**cfg))


def test_n_plus_1_clocks_pause_1_and_msb_first() -> None:
    """001 §4.6: n + 1 clocks, the first read bit is "pause 1", then MSB first; 004 §2.2."""
    line = _line()
    r = line.read(0.0, 25, RATE)
    assert r.start_bit == 1 and r.trailer_bit == 0
    assert r.data == (5 << 13) | 1234
    assert r.end_time == pytest.approx(25 / RATE + 0.5 / RATE)    # 26 clocks
    assert r.warnings == ()
    assert check_readout(r) == MasterStatus.OK


def test_extra_clocks_read_zero() -> None:
    """004 §3.6 TTK70: more than 26 clocks (max 31) -> the additional bits are 0."""
    line = SsiLine(make_encoder("TTK70", Still(0.5)))
    r26 = line.read(0.0, 26, RATE)
    r30 = line.read(1e-3, 30, RATE)
    assert r30.data == r26.data << 4 and r30.trailer_bit == 0
    assert any("31" in w for w in line.read(2e-3, 31, RATE).warnings)


def test_too_few_clocks_fail_the_zero_test() -> None:
    """000 ZERO test / 003 SB.1: a frame longer than the clocks is not terminated with 0."""
    line = _line(pos=4095.9999)          # LSBs are ones
    r = line.read(0.0, 24, RATE)
    assert r.trailer_bit == 1 and MasterStatus.FRAME_ERROR in check_readout(r)


def test_data_wire_break_is_a_data_error() -> None:
    """003 SB.0: with no data the input is LOW -> no start bit -> data error."""
    line = _line()
    line.faults.data_break = True
    r = line.read(0.0, 25, RATE)
    assert r.start_bit == 0 and r.data == 0
    assert MasterStatus.DATA_ERROR in check_readout(r)


def test_clock_wire_break_is_a_frame_error() -> None:
    """003 SB.1: clock wire broken -> no shifting, frame not terminated with zero."""
    line = _line()
    line.faults.clock_break = True
    r = line.read(0.0, 25, RATE)
    assert r.data == (1 << 25) - 1 and r.trailer_bit == 1
    assert MasterStatus.FRAME_ERROR in check_readout(r)
    assert line.latches == 0 and line.last_frame is None


def test_stuck_bit() -> None:
    """A data bit stuck at 1 (sample index 1 = MSB) shows in the value only."""
    line = _line(pos=0.0)
    line.faults.stuck[1] = 1
    r = line.read(0.0, 25, RATE)
    assert r.data == 1 << 24 and check_readout(r) == MasterStatus.OK
    line.faults.clear()
    assert line.read(1e-3, 25, RATE).data == 0


def test_stuck_trailer_is_a_frame_error() -> None:
    """000 ZERO test catches a data line stuck high after the LSB."""
    line = _line()
    line.faults.stuck[26] = 1
    assert MasterStatus.FRAME_ERROR in check_readout(line.read(0.0, 25, RATE))


def test_random_bit_errors_are_seeded() -> None:
    """Noise at a given rate is reproducible with the line seed."""
    reads = []
    for _ in range(2):
        line = _line(seed=7)
        line.faults.bit_error_rate = 0.2
        reads.append([line.read(i * 1e-3, 25, RATE).data for i in range(20)])
    assert reads[0] == reads[1]
    assert any(d != (5 << 13) | 1234 for d in reads[0])


def test_parity_catches_single_bit_errors() -> None:
    """001 §5.5.7: even parity over all previous bits detects a flipped bit."""
    enc = make_encoder("TR_PROGRAMMABLE", Still(3.3), special_bits=(SpecialBit.EVEN_PARITY,))
    line = SsiLine(enc)
    r = line.read(0.0, 25, RATE)
    assert bin(r.data).count("1") % 2 == 0
    line.faults.stuck[3] = 1 - ((r.data >> 22) & 1)
    r2 = line.read(1e-3, 25, RATE)
    assert bin(r2.data).count("1") % 2 == 1


@pytest.mark.parametrize("bursts, flip_burst, mismatch, chosen", [
    (2, None, False, 0), (2, 1, True, 0), (3, 0, False, 1), (3, 2, False, 0),
])
def test_multiple_transmission(bursts, flip_burst, mismatch, chosen) -> None:
    """003 multiple transmission: 2 bursts compare, 3 bursts 2-of-3, first valid value."""
    line = _line()
    mt = MultipleTransmission(line, bursts=bursts)
    good = (5 << 13) | 1234

    if flip_burst is not None:
        orig = line.read
        calls = {"n": 0}

        def read(t, n, rate, **kw):
            r = orig(t, n, rate, **kw)
            calls["n"] += 1
            if calls["n"] - 1 == flip_burst:
                r = r._replace(data=r.data ^ 4)
            return r
        line.read = read          # type: ignore[method-assign]
    res = mt.read(0.0, 25, 1e6)
    assert res.mismatch is mismatch
    assert res.readout is res.bursts[chosen]
    assert res.readout.data == good


def test_repeat_bursts_send_the_latched_word() -> None:
    """003: bursts within tm get the same data word; the line is still low at their start."""
    enc = make_encoder("GENERIC", ConstantVelocity(10.0))
    line = SsiLine(enc)
    res = MultipleTransmission(line, bursts=3).read(0.0, 25, 1e6)
    assert len({b.data for b in res.bursts}) == 1 and line.latches == 1
    assert [b.start_bit for b in res.bursts] == [1, 0, 0]
    assert res.status == MasterStatus.OK


def test_26bit_repeat_repeats_only_once() -> None:
    """001 §5.2.4.3: the second sequence repeats the word, a further one sends a new word."""
    from ssi_bridge.protocol.encoder_config import FrameFormat
    enc = make_encoder("TR_PROGRAMMABLE", ConstantVelocity(100.0),
                       frame_format=FrameFormat.REPEAT_26)
    line = SsiLine(enc)
    r1 = line.read(0.0, 26, 1e6)
    r2 = line.read(r1.end_time + 1e-6, 26, 1e6, expect_repeat=True)
    r3 = line.read(r2.end_time + 1e-6, 26, 1e6, expect_repeat=True)
    assert r1.data == r2.data and line.latches == 2 and r3.data != r1.data
    r4 = line.read(r3.end_time + 30e-6, 26, 1e6)       # after 20 µs: new word
    assert line.latches == 3 and r4.data != r3.data


def test_pause_shorter_than_tm_repeats_and_warns() -> None:
    """004 Figure 3: the pause must exceed tm; inside tm no new value is latched."""
    line = SsiLine(make_encoder("GENERIC", ConstantVelocity(50.0)))
    r1 = line.read(0.0, 25, RATE)
    r2 = line.read(r1.end_time + 10e-6, 25, RATE)
    assert r2.data == r1.data and line.latches == 1
    assert any("tm" in w and "10.0 us" in w for w in r2.warnings)
    r3 = line.read(r2.end_time + 30e-6, 25, RATE)
    assert any("2*tm" in w for w in r3.warnings)      # 001 §4.6 rule: >= 2 tm


@pytest.mark.parametrize("cable, rate, warn", [
    (10.0, 399e3, False), (10.0, 400e3, True), (60.0, 350e3, True), (150.0, 150e3, False),
    (300.0, 150e3, True), (500.0, 50e3, True),
])
def test_cable_table_warning(cable: float, rate: float, warn: bool) -> None:
    """004 §2.7 table: bit rate by cable length, reported with figures."""
    line = _line(cable_length_m=cable)
    r = line.read(0.0, 25, rate)
    assert any("004 §2.7" in w for w in r.warnings) is warn


def test_long_cable_delay_shifts_bits() -> None:
    """004 Figure 2: with tv >= T the master samples one bit late -> ZERO test fails."""
    line = _line(pos=0.0 + 1.5 / 8192, delay_s=1.2e-6, check_cable_table=False)
    r = line.read(0.0, 25, 1e6)
    assert any("tv" in w for w in r.warnings)
    assert r.start_bit == 1 and r.data == 1 << 24 | 0 and r.trailer_bit == 1


def test_slow_clock_below_monoflop_limit() -> None:
    """001 §4.6: T = tm/2 is the lowest frequency; slower, the monoflop releases the line."""
    line = _line(pos=0.0, check_cable_table=False)
    r = line.read(0.0, 25, 40e3)           # T = 25 µs: trailer sampled 37.5 µs after the fall
    assert any("tm/2" in w for w in r.warnings)
    assert r.data == 0 and r.trailer_bit == 1
    r = line.read(1.0, 25, 20e3)           # T/2 = 25 µs > tm: released before every sample
    assert r.data == (1 << 25) - 1 and r.trailer_bit == 1


def test_sync_mode_pause_and_previous_value() -> None:
    """004 §3.4 ATM60 synchronous: the position recorded at the last burst is sent; pause > 150 µs."""
    enc = make_encoder("ATM60", ConstantVelocity(1.0), ssi_mode=SsiMode.SYNC)
    line = SsiLine(enc)
    line.read(0.0, 25, RATE)
    r2 = line.read(1e-3, 25, RATE)
    assert line.last_frame.sample_time == 0.0 and r2.data == 0
    r3 = line.read(r2.end_time + 100e-6, 25, RATE)      # inside tm = 150 µs: repeat
    assert any("synchronous" in w for w in r3.warnings) and line.latches == 2
    line.read(r3.end_time + 400e-6, 25, RATE)
    assert line.last_frame.sample_time == 1e-3 and line.monoflop_s == 150e-6


def test_async_formation_period_same_value_twice() -> None:
    """004 §3.1: asynchronous, position formed every 125 µs; the same value may be read twice."""
    enc = make_encoder("AHM36_MULTI", ConstantVelocity(0.1))
    line = SsiLine(enc)
    a = line.read(130e-6, 26, 1e6)
    b = line.read(200e-6, 26, 1e6)
    assert a.data == b.data
    assert line.last_frame.sample_time == pytest.approx(125e-6)


def test_async_pause_jitter_and_maximum() -> None:
    """004 §3.1: pause constant within ±20 % and at most 600 ms in asynchronous mode."""
    line = SsiLine(make_encoder("AHS36"))
    t = 0.0
    for pause in (1e-3, 1e-3):
        t = line.read(t, 15, RATE).end_time + pause
    r = line.read(t, 15, RATE)
    assert not any("±20" in w for w in r.warnings)
    r = line.read(r.end_time + 1.5e-3, 15, RATE)
    assert any("±20" in w for w in r.warnings)
    r = line.read(r.end_time + 0.7, 15, RATE)
    assert any("600 ms" in w for w in r.warnings)


@pytest.mark.parametrize("data, n, lsb, msb, gray, expect", [
    (0b1011_0110, 8, 0, 0, False, 0b1011_0110),
    (0b1011_0110, 8, 2, 0, False, 0b10_1101),      # LSB side: shifted out
    (0b1011_0110, 8, 0, 3, False, 0b1_0110),       # MSB side: masked to 0
    (0b1011_0110, 8, 1, 2, False, 0b1_1011),
    (0b1100, 4, 0, 0, True, 8),                    # 004 Table 1: Gray 1100 = 8
    ((0b1100 << 3) | 0b101, 7, 3, 0, True, 8),     # error bits shifted out before Gray
])
def test_decode_frame(data, n, lsb, msb, gray, expect) -> None:
    """000 REG_PARA1: invalid LSB bits shifted out, invalid MSB bits masked, Gray -> binary."""
    assert decode_frame(data, n, invalid_lsb=lsb, invalid_msb=msb, gray=gray) == expect


@pytest.mark.parametrize("n, lsb, msb, max_bits", [(0, 0, 0, 32), (33, 0, 0, 32), (65, 0, 0, 64),
                                                   (8, 4, 4, 32)])
def test_decode_frame_limits(n, lsb, msb, max_bits) -> None:
    """000 REG_PARA1: frame 1..32 (64 generic), invalid bits less than the frame length."""
    from ssi_bridge.exceptions import ConfigError
    with pytest.raises(ConfigError):
        decode_frame(0, n, invalid_lsb=lsb, invalid_msb=msb, max_bits=max_bits)


def test_power_fail_bit() -> None:
    """003 SB.2: the last data bit as PowerFail bit."""
    enc = make_encoder("GENERIC", Still(0.0), special_bits=(SpecialBit.POWER_FAIL,))
    line = SsiLine(enc)
    assert check_readout(line.read(0.0, 26, RATE), power_fail_bit=True) == MasterStatus.OK
    enc.power_failure = True
    st = check_readout(line.read(1e-3, 26, RATE), power_fail_bit=True)
    assert st == MasterStatus.POWER_FAILURE
