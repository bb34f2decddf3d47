"""Draw the bit-level timing diagram of one SSI frame, like the pulse diagrams of the manuals.

``ssi_bridge.line`` models the line edge by edge but offers no waveform output, so the levels
are derived here from the documented timing (004 §2.2 Figure 2, 001 §4.6 Figure 4):
``n + 1`` clock periods T; the clock idles high; the first falling edge latches the value;
the master samples on every rising edge, reading first the "pause 1" (idle high), then the
``n`` data bits MSB first, each shifted out by the encoder on the rising edge before; after
the last bit the encoder holds the data line low (monoflop) until ``tm`` after the last
falling edge, then releases it high. Cable delay is not drawn.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from matplotlib.axes import Axes


@dataclass(frozen=True)
class FrameLevels:
    """Step waveforms of one burst: times (s) and levels (0/1) for clock and data."""

    clock_t: np.ndarray
    clock: np.ndarray
    data_t: np.ndarray
    data: np.ndarray
    #: master sample instants (rising edges): pause bit first, then MSB..LSB
    samples: np.ndarray
    period: float
    monoflop: float


def frame_levels(value: int, n_bits: int, bit_rate_hz: float, monoflop_s: float) -> FrameLevels:
    """Clock and data levels of a burst that reads ``value`` (``n_bits`` bits, MSB first).

    :param bit_rate_hz: the SSI clock rate
    :param monoflop_s: the monoflop time tm (s)
    :raises ValueError: ``n_bits`` below 1, or a rate or monoflop time not positive
    """
    if n_bits < 1 or bit_rate_hz <= 0 or monoflop_s <= 0:
        raise ValueError("need n_bits >= 1, bit rate > 0 and monoflop > 0")
    period = 1.0 / bit_rate_hz
    half = period / 2
    lead = period                           # idle time drawn before the burst
    clock_t, clock = [-lead], [1]
    for k in range(n_bits + 1):             # falling edge at k*T, rising at k*T + T/2
        clock_t += [k * period, k * period + half]
        clock += [0, 1]
    last_fall = n_bits * period
    end = last_fall + max(monoflop_s, half) + 2 * period
    clock_t.append(end)
    clock.append(1)
    bits = [(value >> (n_bits - 1 - i)) & 1 for i in range(n_bits)]
    data_t, data = [-lead], [1]             # idle high = the "pause 1" the master reads first
    for i, bit in enumerate(bits):          # bit i shifted out at rising edge i
        data_t.append(half + i * period)
        data.append(bit)
    data_t += [half + n_bits * period, max(last_fall + monoflop_s, half + n_bits * period), end]
    data += [0, 1, 1]                       # monoflop low, then idle high
    samples = np.array([half + k * period for k in range(n_bits + 1)])
    return FrameLevels(np.array(clock_t), np.array(clock), np.array(data_t), np.array(data),
                       samples, period, monoflop_s)


def draw_frame(ax: Axes, value: int, n_bits: int, bit_rate_hz: float, monoflop_s: float,
               error_bits: int = 0, title: str = "") -> FrameLevels:
    """Draw clock and data on ``ax`` (µs) with latch edge, pause bit, MSB..LSB and tm.

    :param ax: the matplotlib axes to draw on
    :param value: the frame's bits, first transmitted = MSB
    :param n_bits: the frame length
    :param bit_rate_hz: the SSI clock rate
    :param monoflop_s: the monoflop time tm (s)
    :param error_bits: how many low bits are error or special bits (highlighted)
    :param title: the axes' title
    :returns: the clock and data levels drawn
    """
    lv = frame_levels(value, n_bits, bit_rate_hz, monoflop_s)
    us = 1e6
    ax.step(lv.clock_t * us, lv.clock + 2.0, where="post", color="tab:blue", lw=1.5)
    ax.step(lv.data_t * us, lv.data * 1.0, where="post", color="tab:red", lw=1.5)
    ax.set_yticks([0.5, 2.5], ["Data", "Clock"])
    ax.set_ylim(-1.2, 4.2)
    ax.set_xlabel("time from latch edge [µs]")
    ax.axvline(0, color="k", ls="--", lw=0.8)
    ax.annotate("latch (1st falling edge)", (0, 3.1), (lv.period * us * 0.3, 3.7),
                arrowprops={"arrowstyle": "->"}, fontsize=8)
    for ts in lv.samples:                   # master sample instants
        ax.axvline(ts * us, color="0.85", lw=0.6, zorder=0)
    t_bit = lv.period * us
    for i in range(n_bits):                 # bit i is on the line from rising edge i to i+1
        bit_no = n_bits - 1 - i
        err = bit_no < error_bits
        ax.text((i + 1) * t_bit, 1.15, str(bit_no), ha="center", fontsize=6,
                color="tab:orange" if err else "0.3")
        if err:
            ax.axvspan((i + 0.5) * t_bit, (i + 1.5) * t_bit, ymin=0.05, ymax=0.45,
                       color="tab:orange", alpha=0.2)
    ax.text(lv.samples[1] * us, -0.8, "MSB", fontsize=8)
    ax.text(lv.samples[-1] * us, -0.8, "LSB", fontsize=8, ha="right")
    ax.text(lv.samples[0] * us - lv.period * us * 0.3, -0.8, "pause 1", fontsize=8,
            ha="right")
    last_fall = n_bits * lv.period
    ax.annotate("", (last_fall * us, -0.4), ((last_fall + monoflop_s) * us, -0.4),
                arrowprops={"arrowstyle": "<->", "color": "tab:green"})
    ax.text((last_fall + monoflop_s / 2) * us, -0.3, f"tm {monoflop_s * us:.0f} µs",
            ha="center", fontsize=8, color="tab:green")
    ax.set_title(title or f"SSI frame 0x{value:X}: {n_bits} bits at "
                 f"{bit_rate_hz / 1e3:.0f} kHz" + (f", {error_bits} error/special bits"
                                                    if error_bits else ""), fontsize=10)
    return lv
