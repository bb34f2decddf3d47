"""SSI timing rules a master's burst is checked against; each gives a warning with figures.

* 004 §2.7 table: recommended bit rate by cable length (< 50 m: < 400 kHz, < 100 m:
  < 300 kHz, < 200 m: < 200 kHz, < 400 m: < 100 kHz); 004 §2.1: at most 2 MHz;
* 001 §4.6: the lowest clock frequency follows from the monoflop time, T = tm / 2, and the
  pause between two bursts must be at least 2 · tm; 004 Figure 3: the pause must exceed tm;
* 004 Figure 2: the data delay tv must stay below T / 2;
* 004 §3.1 (asynchronous mode): pauses constant within ±20 %, never above 600 ms;
  synchronous mode: pause at least 150 µs / 200 µs (004 §3.1, §3.4);
* 004 §3.6 (TTK70): at most 31 clocks per burst.
"""

from __future__ import annotations

from ssi_bridge.protocol.encoder_config import EncoderConfig, SsiMode

#: (cable shorter than m, recommended bit rate below Hz), 004 §2.7
CABLE_TABLE: tuple[tuple[float, float], ...] = (
    (50.0, 400e3), (100.0, 300e3), (200.0, 200e3), (400.0, 100e3))
#: highest SSI bit rate (004 §2.1)
MAX_BIT_RATE_HZ = 2e6
#: signal propagation in twisted-pair cable (s/m), clock out and data back
CABLE_DELAY_S_PER_M = 5e-9
#: encoder delay without cable, tv > 100 ns (001 §4.6)
BASE_DELAY_S = 100e-9


def recommended_bit_rate(cable_length_m: float) -> float | None:
    """Upper bit rate the 004 §2.7 table recommends for a cable, None beyond 400 m.

    :param cable_length_m: the cable (m)
    """
    for length, rate in CABLE_TABLE:
        if cable_length_m < length:
            return rate
    return None


def data_delay(cable_length_m: float) -> float:
    """tv: encoder delay plus the round trip of clock and data over the cable (s).

    :param cable_length_m: the cable (m)
    """
    return BASE_DELAY_S + 2.0 * CABLE_DELAY_S_PER_M * cable_length_m


def static_warnings(enc: EncoderConfig, cable_length_m: float, tm: float, tv: float,
                    n_bits: int, bit_rate_hz: float, check_cable_table: bool) -> tuple[str, ...]:
    """Warnings that depend only on the configuration and the burst shape.

    :param enc: the encoder's configuration
    :param cable_length_m: the cable (m)
    :param tm: the monoflop time (s)
    :param tv: the data delay (s)
    :param n_bits: data bits per burst
    :param bit_rate_hz: the clock rate
    :param check_cable_table: also hold the bit rate against 004 §2.7's cable table
    """
    out: list[str] = []
    period = 1.0 / bit_rate_hz
    if bit_rate_hz > MAX_BIT_RATE_HZ:
        out.append(f"bit rate {bit_rate_hz / 1e3:.1f} kHz above the SSI maximum 2000 kHz (004 §2.1)")
    if check_cable_table:
        rec = recommended_bit_rate(cable_length_m)
        if rec is None:
            out.append(f"cable {cable_length_m:.1f} m longer than the 400 m of the 004 §2.7 table")
        elif bit_rate_hz >= rec:
            out.append(f"bit rate {bit_rate_hz / 1e3:.1f} kHz not below {rec / 1e3:.0f} kHz "
                       f"recommended for a {cable_length_m:.1f} m cable (004 §2.7)")
    if period > tm / 2.0:
        out.append(f"clock period {period * 1e6:.2f} us > tm/2 = {tm * 0.5e6:.2f} us: "
                   f"bit rate below the monoflop limit (001 §4.6)")
    if tv >= period / 2.0:
        out.append(f"data delay tv {tv * 1e9:.0f} ns >= T/2 = {period * 0.5e9:.0f} ns (004 Figure 2)")
    if enc.max_clocks is not None and n_bits + 1 > enc.max_clocks:
        out.append(f"{n_bits + 1} clocks exceed the encoder maximum of {enc.max_clocks} (004 §3.6)")
    return tuple(out)


def pause_warnings(enc: EncoderConfig, pause: float, prev_pause: float | None,
                   tm: float) -> list[str]:
    """Warnings about the pause since the previous burst (s).

    :param enc: the encoder's configuration
    :param pause: the pause since the previous burst (s)
    :param prev_pause: the pause before that (None: first)
    :param tm: the monoflop time (s)
    """
    out: list[str] = []
    if pause < tm:
        out.append(f"pause {pause * 1e6:.1f} us < tm {tm * 1e6:.1f} us: monoflop still "
                   f"active, previous value repeated (004 Figure 3)")
    elif pause < 2.0 * tm:
        out.append(f"pause {pause * 1e6:.1f} us < 2*tm {2e6 * tm:.1f} us (001 §4.6)")
    if enc.ssi_mode is SsiMode.SYNC and pause < enc.min_pause_s:
        out.append(f"pause {pause * 1e6:.1f} us < {enc.min_pause_s * 1e6:.0f} us required in "
                   f"synchronous SSI mode (004 §3.1/§3.4)")
    if enc.ssi_mode is SsiMode.ASYNC:
        if enc.async_max_pause_s is not None and pause > enc.async_max_pause_s:
            out.append(f"pause {pause * 1e3:.1f} ms > {enc.async_max_pause_s * 1e3:.0f} ms "
                       f"allowed in asynchronous SSI mode (004 §3.1)")
        tol = enc.async_pause_tolerance
        if tol is not None and prev_pause and abs(pause - prev_pause) > tol * prev_pause:
            out.append(f"pause {pause * 1e6:.1f} us deviates {100 * (pause / prev_pause - 1):+.0f} % "
                       f"from the previous {prev_pause * 1e6:.1f} us, beyond ±{tol * 100:.0f} % (004 §3.1)")
    return out
