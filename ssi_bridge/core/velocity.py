"""The velocity estimate published in ``joint_states``: a finite difference over a window.

ROS-free so it is unit-tested with exact numbers; the error bound is in docs/node.md.
"""

from __future__ import annotations

import math

from collections import deque

from ssi_bridge.exceptions import ConfigError
from ssi_bridge.core.joint_scale import JointScale


class VelocityEstimator:
    """Velocity from the last ``window`` samples: (newest - oldest) / (their time difference).

    Differences are unwrapped modulo the encoder range, so crossing the multiturn (or
    round-axis) wrap gives the true speed, not a spike. For constant speed the estimate is
    exact up to one count over the window; for a varying speed it lags by (window - 1) / 2
    samples — the documented trade of quantisation noise against delay (docs/node.md).

    Unknown is NaN: before two samples, after :meth:`reset`, and for a sample whose step
    from the previous one is faster than ``max_speed`` (joint units/s; 0 = no check), which
    is counted in :attr:`implausible` and restarts the estimate from that sample.

    :param scale: the joint's counts -> units scale (its modulus unwraps the differences)
    :param window: samples the difference spans (>= 2)
    :param max_speed: the plausible speed limit in joint units/s (>= 0; 0: no check)
    :raises ConfigError: ``window`` below 2 or ``max_speed`` negative or NaN
    """

    def __init__(self, scale: JointScale, window: int = 5, max_speed: float = 0.0) -> None:
        if window < 2:
            raise ConfigError(f"velocity window {window} must be >= 2 samples")
        if not max_speed >= 0:
            raise ConfigError(f"max_speed {max_speed} must be >= 0 (0: no check)")
        self._scale = scale
        #: the scale's constants, read every sample (JointScale is frozen)
        self._unit_per_count = scale.unit_per_count
        self._modulus = scale.modulus or 0
        self._half = self._modulus >> 1
        self.window = window
        self.max_speed = max_speed
        #: samples whose step exceeded ``max_speed`` (since construction)
        self.implausible = 0
        #: the last sample given to :meth:`update` was such a jump
        self.last_implausible = False
        self._samples: deque[tuple[float, int]] = deque(maxlen=window)
        self._unwrapped = 0
        self._last_raw: int | None = None
        self._last_t: float | None = None
        self._ignore_until: float | None = None
        self._held: float | None = None

    @property
    def scale(self) -> JointScale:
        """The counts -> units scale the estimate uses."""
        return self._scale

    def reset(self, after: float | None = None, hold: bool = False) -> None:
        """Forget history, e.g. after a preset or a fault (the next estimate restarts).

        ``after``: also ignore samples latched at or before this time (``math.inf``: all
        until the next reset) — those a cycle may still deliver from before a preset took
        effect. ``hold``: report the current estimate until two new samples give a fresh
        one; a preset moves the zero point, not the shaft, so the speed does not jump.
        """
        held = self.velocity if hold else None
        self._samples.clear()
        self._last_raw = None
        self._last_t = None
        self._unwrapped = 0
        self._ignore_until = after
        self._held = held

    def update(self, t: float, counts: int) -> float:
        """Add a sample and return the velocity estimate.

        :param t: the sample's latch time (s)
        :param counts: its raw REG_SSI_POS (unsigned 32-bit counts)
        :returns: the estimate in joint units/s; NaN while unknown (see the class)
        """
        self.last_implausible = False
        ignore = self._ignore_until
        if ignore is not None and t <= ignore:
            return self.velocity
        raw = counts & 0xFFFF_FFFF  # to_int32, inline: once per joint and cycle
        if raw & 0x8000_0000:
            raw -= 0x1_0000_0000
        last_raw = self._last_raw
        if last_raw is None:
            unwrapped = raw
        else:
            step = raw - last_raw
            modulus = self._modulus
            if modulus:
                half = self._half
                step = (step + half) % modulus - half
            last_t = self._last_t
            max_speed = self.max_speed
            if (max_speed > 0 and last_t is not None and t > last_t
                    and abs(step * self._unit_per_count) > max_speed * (t - last_t)):
                # faster than the joint can move: this sample's speed is unknown and the
                # window restarts here, so the jump never enters an estimate
                self.implausible += 1
                self.last_implausible = True
                self._samples.clear()
                self._held = None
                self._last_raw, self._last_t, self._unwrapped = raw, t, raw
                self._samples.append((t, raw))
                return math.nan
            unwrapped = self._unwrapped + step
        self._unwrapped = unwrapped
        self._last_raw = raw
        samples = self._samples
        if samples and t <= samples[-1][0]:
            return self.velocity
        self._last_t = t
        samples.append((t, unwrapped))
        if len(samples) < 2:
            return self.velocity
        t0, c0 = samples[0]  # the property's difference, with the newest sample at hand
        return (unwrapped - c0) / (t - t0) * self._unit_per_count

    @property
    def velocity(self) -> float:
        """Current estimate in joint units per second (NaN before two samples, or the held one)."""
        if len(self._samples) < 2:
            return self._held if self._held is not None else math.nan
        samples = self._samples
        (t0, c0), (t1, c1) = samples[0], samples[-1]
        return (c1 - c0) / (t1 - t0) * self._unit_per_count
