"""State behind the TR SSI special bits (001 §5.5) and the cam / overspeed monitors (§5.4).

The encoder evaluates these each time it forms a frame (``SsiEncoder.frame_at``):

* cams (§5.5.1): set while the value is on or above the switch-on point and below the
  switch-off point; with switch-on > switch-off the cam "circulates" (set above on OR
  below off);
* overspeed (§5.5.2): |speed| above ``overspeed_rpm``;
* going up / going down (§5.5.3): set when the value moves in that direction, cleared
  after ``standstill_s`` (50 ms) without a step; a reversal (or a start from standstill)
  is only signalled after the value has moved *more than* ``hysteresis_steps`` (one step)
  away from the turning point, so a one-step vibration is not reported as motion;
* UP (§5.5.4) set by going up, cleared by going down; moving (§5.5.5) = up or down;
* dynamic error (§5.5.6): 250 Hz square wave while healthy, frozen while in error;
* toggle (§5.5.8): changes after each transmission, errors or not.

Parity (§5.5.7) depends on the other frame bits, so ``SsiEncoder`` computes it last.
"""

from __future__ import annotations

from ssi_bridge.protocol.encoder_config import CAM_BITS, EncoderConfig, SpecialBit

#: dynamic error square wave (001 §5.5.6): 250 Hz -> the level changes every 2 ms
DYNAMIC_ERROR_HZ = 250.0


def cam_active(value: int, on: int, off: int) -> bool:
    """Cam output for ``value`` with switch points ``on`` / ``off`` (001 §5.4.1, §5.5.1)."""
    if on <= off:
        return on <= value < off
    return value >= on or value < off


class DirectionMonitor:
    """Going up / going down with stand-still time and one-step hysteresis (001 §5.5.3).

    :param standstill_s: no step for this long is a stand-still (s)
    :param hysteresis_steps: steps back before a reversal counts
    """

    def __init__(self, standstill_s: float, hysteresis_steps: int) -> None:
        self.standstill_s = standstill_s
        self.hysteresis = hysteresis_steps
        self.direction = 0          # +1 going up, -1 going down, 0 stand-still
        self.up = False             # UP bit (001 §5.5.4), kept through stand-still
        self._anchor: int | None = None   # turning point / last extreme value
        self._last_step_t = 0.0

    def update(self, t: float, value: int) -> int:
        """Feed the value formed at ``t``; return the direction to signal."""
        if self._anchor is None:
            self._anchor, self._last_step_t = value, t
            return 0
        d = self.direction
        moved = value - self._anchor
        if d != 0 and moved * d > 0:                 # further in the same direction
            self._anchor, self._last_step_t = value, t
        elif abs(moved) > self.hysteresis:           # start or reversal beyond hysteresis
            self.direction = 1 if moved > 0 else -1
            self.up = self.direction > 0
            self._anchor, self._last_step_t = value, t
        if self.direction != 0 and t - self._last_step_t >= self.standstill_s:
            self.direction = 0
            self._anchor = value
        return self.direction


class SpecialState:
    """Per-encoder state for the special bits; ``levels()`` gives the logical bit values.

    :param cfg: the encoder's layout (which special bits it has, its limits)
    """

    def __init__(self, cfg: EncoderConfig) -> None:
        self.cfg = cfg
        self.monitor = DirectionMonitor(cfg.standstill_s, cfg.hysteresis_steps)
        self.toggle = 0
        self._dyn_frozen: int | None = None

    def active(self, t: float, value: int, speed_rps: float,
               errors: frozenset[SpecialBit], power_fail: bool) -> set[SpecialBit]:
        """Set of special bits (excluding parity) that are logically active.

        :param t: the formation time (s)
        :param value: the output value (steps)
        :param speed_rps: the shaft's speed (rev/s or m/s)
        :param errors: the error bits raised
        :param power_fail: the supply is below its limit
        """
        cfg = self.cfg
        out: set[SpecialBit] = set(errors)
        if power_fail:
            out.add(SpecialBit.POWER_FAIL)
        for bit, (on, off) in zip(CAM_BITS, cfg.cams):
            if cam_active(value, on, off):
                out.add(bit)
        if abs(speed_rps) * 60.0 > cfg.overspeed_rpm:
            out.add(SpecialBit.OVERSPEED)
        d = self.monitor.update(t, value)
        if d > 0:
            out.update((SpecialBit.GOING_UP, SpecialBit.MOVING))
        elif d < 0:
            out.update((SpecialBit.GOING_DOWN, SpecialBit.MOVING))
        if self.monitor.up:
            out.add(SpecialBit.UP)
        if errors:
            if self._dyn_frozen is None:
                self._dyn_frozen = int(t * 2.0 * DYNAMIC_ERROR_HZ) & 1
            dyn = self._dyn_frozen
        else:
            self._dyn_frozen = None
            dyn = int(t * 2.0 * DYNAMIC_ERROR_HZ) & 1
        if dyn:
            out.add(SpecialBit.DYNAMIC_ERROR)
        if self.toggle:
            out.add(SpecialBit.TOGGLE)
        self.toggle ^= 1
        return out
