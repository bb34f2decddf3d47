"""The velocity estimate published in ``joint_states``: a finite difference over a window.

ROS-free so it is unit-tested with exact numbers; the error bound is in docs/node.md.
"""

from __future__ import annotations

from collections import deque

from ssi_bridge.exceptions import ConfigError
from ssi_bridge.ros.joint_scale import JointScale, to_int32


class VelocityEstimator:
    """Velocity from the last ``window`` samples: (newest - oldest) / (their time difference).

    Differences are unwrapped modulo the encoder range, so crossing the multiturn (or
    round-axis) wrap gives the true speed, not a spike. For constant speed the estimate is
    exact up to one count over the window; for a varying speed it lags by (window - 1) / 2
    samples — the documented trade of quantisation noise against delay (docs/node.md).
    """

    def __init__(self, scale: JointScale, window: int = 5) -> None:
        if window < 2:
            raise ConfigError(f"velocity window {window} must be >= 2 samples")
        self._scale = scale
        self._samples: deque[tuple[float, int]] = deque(maxlen=window)
        self._unwrapped = 0
        self._last_raw: int | None = None
        self._ignore_until: float | None = None
        self._held: float | None = None

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
        self._unwrapped = 0
        self._ignore_until = after
        self._held = held

    def update(self, t: float, counts: int) -> float:
        """Add a sample (latch time in s, raw REG_SSI_POS) and return the velocity estimate."""
        if self._ignore_until is not None and t <= self._ignore_until:
            return self.velocity
        raw = to_int32(counts)
        if self._last_raw is None:
            self._unwrapped = raw
        else:
            step = raw - self._last_raw
            modulus = self._scale.modulus
            if modulus:
                step = (step + modulus // 2) % modulus - modulus // 2
            self._unwrapped += step
        self._last_raw = raw
        if self._samples and t <= self._samples[-1][0]:
            return self.velocity
        self._samples.append((t, self._unwrapped))
        return self.velocity

    @property
    def velocity(self) -> float:
        """Current estimate in joint units per second (0.0 before two samples, or the held one)."""
        if len(self._samples) < 2:
            return self._held if self._held is not None else 0.0
        (t0, c0), (t1, c1) = self._samples[0], self._samples[-1]
        return (c1 - c0) / (t1 - t0) * self._scale.unit_per_count
