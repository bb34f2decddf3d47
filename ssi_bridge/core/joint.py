"""One joint of the bridge, ROS-free: what a sample of each cycle becomes, and the joint's health.

A :class:`Joint` owns everything the node knows of one encoder channel: the counts -> units
scale for the REG_PARA1 in force, the velocity filter, the frame checks, the counters, the
windowed and debounced health, and the REG_PARA1 gate. :meth:`Joint.update` takes the
channel's newest sample of one SYNC and returns what is published for it
(:class:`JointOutput`); the rules (docs/node.md):

* a sample latched while REG_PARA1 changed is unknown: position and velocity NaN;
* a frame that failed its parity / filler / check-sum check (001 5.5.7, 004 3) keeps the last
  good position and speed;
* while the module does not measure (ERR_SSI, ERR_PARA, STS_STOP: 000 "Error detection") the
  position is the last REG_SSI_POS and the speed unknown (NaN); the estimate restarts;
* no fresh sample for ``stale_cycles`` cycles: the speed is unknown (NaN), the estimate restarts;
* otherwise the estimate takes the fresh sample; a step faster than ``max_speed`` counts as
  implausible (WARN).

Every cycle, published or not, counts for the health at its SYNC's wire time.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from ssi_bridge.core.frame_watch import FrameWatch, edges
from ssi_bridge.core.health import OK, WARN, ChannelCounters, ChannelHealth, Level
from ssi_bridge.core.joint_scale import JointScale, to_int32
from ssi_bridge.core.velocity import VelocityEstimator
from ssi_bridge.exceptions import ConfigError
from ssi_bridge.protocol.encoder_config import EncoderConfig
from ssi_bridge.protocol.families import family_max_speed
from ssi_bridge.protocol.frame_check import CLEAN
from ssi_bridge.protocol.images import ModuleStatus
from ssi_bridge.protocol.joint_encoder import count_factor, joint_config, para1_mismatch
from ssi_bridge.protocol.settings import JointSettings

#: status bits under which the module does not acquire (000 "Error detection / messages")
NOT_MEASURING = int(ModuleStatus.ERR_SSI | ModuleStatus.ERR_PARA | ModuleStatus.STS_STOP)
#: status bits counted as error cycles
ERRORS = int(ModuleStatus.ERR_SSI | ModuleStatus.ERR_PARA)


def spec_max_speed(family: str, linear: bool | None = None) -> float:
    """The physical speed limit (rad/s or m/s) of a family, what ``max_speed: -1`` means.

    Never off: no family's manual states a shaft speed (the TR overspeed of 001 §5.4.2 is
    the speed monitor's threshold), so each takes the documented default (12000 1/min
    rotary, 10 m/s linear; :func:`~ssi_bridge.protocol.families.family_max_speed`,
    docs/node.md).
    ``linear``: the joint's kind where it differs from the family's.
    """
    return family_max_speed(family, linear).limit


def encoder_layout(joint: JointSettings) -> tuple[EncoderConfig | None, str]:
    """The joint's encoder layout from its parameters, or (None, why not)."""
    try:
        return joint_config(joint), ""
    except ConfigError as err:
        return None, str(err)


def joint_scale(joint: JointSettings, cfg: EncoderConfig | None, para1: int) -> JointScale:
    """Counts -> units for ``para1``: one path for simulated and real stations.

    The encoder layout the joint's parameters describe (family preset, ``steps_per_rev`` /
    ``revolutions`` / ``measuring_step``) and REG_PARA1's frame length and invalid LSB bits
    (:func:`count_factor`, 000 Table 19). Without a usable layout, ``steps_per_rev`` /
    ``revolutions`` or ``measuring_step`` are taken as the resolution of REG_SSI_POS itself.

    :param joint: the joint's parameters (direction, and the fallback resolution)
    :param cfg: the encoder layout (:func:`encoder_layout`), None when there is no usable one
    :param para1: the module's REG_PARA1 value (frame length, invalid LSB bits)
    :returns: the scale from REG_SSI_POS counts to joint units
    """
    if cfg is not None:
        factor = count_factor(cfg, para1)
        if cfg.linear:
            return JointScale(linear=True, measuring_step_m=cfg.measuring_step_m / factor,
                              direction=joint.direction)
        return JointScale(counts_per_rev=cfg.steps_per_unit * factor,
                          revolutions=cfg.revolutions_numerator / cfg.revolutions_divisor,
                          direction=joint.direction)
    if joint.measuring_step > 0:
        return JointScale(linear=True, measuring_step_m=joint.measuring_step,
                          direction=joint.direction)
    return JointScale(counts_per_rev=joint.steps_per_rev or 8192,
                      revolutions=joint.revolutions or 4096, direction=joint.direction)


@dataclass(slots=True)  # one per joint and cycle
class JointOutput:
    """What one cycle of a joint publishes, and what it has to say on ``~/events``."""

    #: joint units (rad or m), NaN while unknown
    position: float
    #: joint units/s, NaN while unknown
    velocity: float
    #: (success, sentence) for ``~/events``: frame-check edges and failures (as a rule none:
    #: the shared empty tuple)
    events: Sequence[tuple[bool, str]] = ()


class Joint:
    """The rules of one joint, fed one sample per cycle (see the module docstring).

    :param settings: the joint's parameters
    :param velocity_window: samples the velocity fit spans
    :param max_speed: ``<joint>.max_speed`` (joint units/s; -1: the family's physical limit,
        :func:`spec_max_speed`, on for every family; 0: off)
    :param stale_cycles: cycles without a fresh sample before the joint is STALE
    """

    def __init__(self, settings: JointSettings, *, velocity_window: int, max_speed: float,
                 stale_cycles: int) -> None:
        self.settings = settings
        self.name = settings.name
        self.slot = settings.slot
        #: the encoder layout from the parameters (None: unknown, ``layout_problem`` says why)
        self.config, self.layout_problem = encoder_layout(settings)
        self.stale_cycles = stale_cycles
        self._window = velocity_window
        self.max_speed = self._limit(max_speed)
        #: REG_PARA1 the module holds, as written or read back (one truth: :meth:`adopt_para1`)
        self.para1 = settings.para1
        #: why the REG_PARA1 in force does not fit the encoder (a WARN), or ""
        self.para1_note = self._note(self.para1)
        self.scale = joint_scale(settings, self.config, self.para1)
        #: the scale's joint units per count, read every cycle (follows ``scale``)
        self._unit_per_count = self.scale.unit_per_count
        self.velocity = VelocityEstimator(self.scale, velocity_window, self.max_speed)
        #: samples latched at or before this wire time may carry another REG_PARA1 (inf: a
        #: change is in flight): their position and velocity are unknown (NaN)
        self.para1_since = -math.inf
        self.frames = FrameWatch(self.config, self.para1)
        self.counters = ChannelCounters()
        self.health = ChannelHealth()
        #: the last published position (joint units)
        self.position = 0.0
        #: whether this cycle's sample was an implausible step, for :meth:`settle`
        self._implausible = False

    # -- settings that change at run time ---------------------------------------------------
    def _limit(self, max_speed: float) -> float:
        """``max_speed`` itself, or for -1 the family's limit in the joint's units."""
        if max_speed >= 0:
            return max_speed
        linear = (self.config.linear if self.config is not None
                  else self.settings.measuring_step > 0)  # as joint_scale decides
        return spec_max_speed(self.settings.family, linear)

    def set_max_speed(self, max_speed: float) -> None:
        """``<joint>.max_speed``: -1 = the family's limit, 0 = off (ConfigError otherwise < 0)."""
        if not (max_speed >= 0 or max_speed == -1):
            raise ConfigError(f"{self.name}.max_speed {max_speed}: >= 0 (0: off) or -1 "
                              "(the encoder family's limit)")
        self.max_speed = self._limit(max_speed)
        self.velocity.max_speed = self.max_speed

    def set_velocity_window(self, window: int) -> None:
        """A new window for the velocity fit (the estimate restarts)."""
        self._window = window
        self.velocity = VelocityEstimator(self.scale, window, self.max_speed)

    # -- the REG_PARA1 gate -----------------------------------------------------------------
    def _note(self, para1: int) -> str:
        mismatch = para1_mismatch(self.config, para1) if self.config is not None else None
        return f"REG_PARA1 0x{para1:08X} does not fit the encoder: {mismatch}" if mismatch else ""

    def para1_changing(self) -> None:
        """A REG_PARA1 change (write or LD20 reset) starts: samples are unknown until adopted."""
        self.para1_since = math.inf
        self.velocity.reset(after=math.inf)

    def adopt_para1(self, value: int, since: float) -> None:
        """The module now holds ``value``: scale, estimate and frame checks follow.

        Samples latched before wire time ``since`` were acquired with the old REG_PARA1 and are
        unknown (NaN).
        """
        self.scale = joint_scale(self.settings, self.config, value)
        self._unit_per_count = self.scale.unit_per_count
        estimator = VelocityEstimator(self.scale, self._window, self.max_speed)
        estimator.reset(after=since)
        self.velocity = estimator
        self.frames.set_para1(value)
        self.para1 = value
        self.para1_note = self._note(value)
        self.para1_since = since

    # -- one cycle --------------------------------------------------------------------------
    @property
    def level(self) -> Level:
        """The level the joint's diagnostics publish (the health's, WARN for a REG_PARA1 note)."""
        return max(self.health.level, WARN if self.para1_note else OK)

    def observe(self, now: float, *, stale: bool, implausible: bool, seq: int | None = None,
                lost: float | None = None) -> None:
        """One SYNC (wire time ``now``, number ``seq``) for the joint's windowed health.

        :param stale: no complete fresh sample of this SYNC
        :param implausible: the SYNC's sample was an implausible jump
        :param lost: the share of the joint's data of this SYNC that is missing (default: all
            of it when ``stale``), as :meth:`ChannelHealth.observe` takes it
        """
        counters = self.counters
        image = counters.last_image
        self.health.observe(now, stale=stale, implausible=implausible,
                            sts=image[7] if image is not None else None,  # last_sts
                            consecutive_stale=counters.consecutive_stale,
                            stale_limit=self.stale_cycles, seq=seq, lost=lost,
                            silent=counters.consecutive_silent >= self.stale_cycles)

    def quiet(self, now: float) -> None:
        """A period without SYNC (listen-only) ending at ``now`` (s): a stale cycle."""
        self.counters.stale_cycles += 1
        self.counters.consecutive_stale += 1
        self.counters.consecutive_silent += 1
        self.observe(now, stale=True, implausible=False)

    def settle(self, seq: int, settled: tuple[float, float] | None) -> None:
        """The health of the SYNC before ``seq``, judged now, after :meth:`output` or
        :meth:`leave_out` of SYNC ``seq``: what :meth:`update` and :meth:`set_aside` do last,
        for a caller that publishes the cycle first. An answer on the wire in time but handled
        late is counted for its SYNC, so the stale ratio measures the bus.

        :param settled: (wire time, share not vouched) of the SYNC before, None for the first
        """
        if settled is not None:
            t_prev, lost = settled
            self.observe(t_prev, stale=lost > 0, implausible=self._implausible, seq=seq - 1,
                         lost=lost)

    def set_aside(self, seq: int, settled: tuple[float, float] | None, reason: str,
                  image: bytes = b"", position: int | None = None) -> None:
        """No sample of this SYNC can be vouched for (``reason``, ``core/cycle_log.py``): the
        joint is left out of the cycle, which counts as a stale cycle.

        ``image``/``position``: what did arrive (kept for the status bits and diagnostics, not
        published). After ``stale_cycles`` of them the velocity estimate restarts, so a gap
        never becomes a speed. ``settled`` as for :meth:`update`; ``seq``: this SYNC's number.
        """
        self.leave_out(reason, image, position)
        self.settle(seq, settled)

    def leave_out(self, reason: str, image: bytes = b"", position: int | None = None) -> None:
        """:meth:`set_aside` but the health of the SYNC before (:meth:`settle`, due next).

        :param reason: why no sample is vouched for (kept in the counters for diagnostics)
        :param image: the process input image that did arrive, if any
        :param position: the REG_SSI_POS that did arrive, if any
        """
        self._implausible = False
        counters = self.counters
        counters.stale_cycles += 1
        counters.consecutive_stale += 1
        if image or position is not None:
            counters.set_aside += 1
            counters.consecutive_silent = 0
        else:
            counters.consecutive_silent += 1
        counters.last_reason = reason
        if image:
            counters.last_image = image
        if position is not None:
            counters.last_position = position
        if counters.consecutive_stale >= self.stale_cycles:
            self.velocity.reset()

    def count(self, sample_time: float, image: bytes, reg_ssi_pos: int, t_sync: float) -> bool:
        """Count the newest sample (latched at ``sample_time``) for the SYNC at ``t_sync``.

        :param image: its 8-byte process input image (byte 7: status)
        :param reg_ssi_pos: its REG_SSI_POS (raw counts)
        :returns: True when it is fresh (latched at this SYNC)
        """
        counters = self.counters
        fresh = sample_time >= t_sync
        if fresh:
            counters.samples += 1
            counters.consecutive_stale = 0
            counters.consecutive_silent = 0
        else:
            counters.stale_cycles += 1
            counters.consecutive_stale += 1
        counters.last_image = image
        counters.last_position = reg_ssi_pos
        counters.last_reason = ""
        if image[7] & ERRORS:
            counters.error_cycles += 1
        return fresh

    def update(self, sample_time: float, image: bytes, reg_ssi_pos: int, t_sync: float, *,
               seq: int, settled: tuple[float, float] | None) -> JointOutput:
        """What the joint publishes for the sample it has at the SYNC ``t_sync`` (number
        ``seq``). Call :meth:`count` first; ``settled``: (wire time, share not vouched) of the
        SYNC before, judged once its window is over (None for the first SYNC).

        :param sample_time: latch time of the sample (s, the SYNC's clock)
        :param image: its 8-byte process input image
        :param reg_ssi_pos: its REG_SSI_POS (raw counts)
        :returns: the position, velocity and events to publish
        """
        out = self.output(sample_time, image, reg_ssi_pos, t_sync)
        self.settle(seq, settled)
        return out

    def output(self, sample_time: float, image: bytes, reg_ssi_pos: int,
               t_sync: float) -> JointOutput:
        """:meth:`update` but the health of the SYNC before (:meth:`settle`, due next).

        :param sample_time: latch time of the sample (s, the SYNC's clock)
        :param image: its 8-byte process input image
        :param reg_ssi_pos: its REG_SSI_POS (raw counts)
        :param t_sync: wire time of this SYNC (a sample latched at or after it is fresh)
        :returns: the position, velocity and events to publish
        """
        counters = self.counters
        estimator = self.velocity
        position = to_int32(reg_ssi_pos) * self._unit_per_count  # JointScale.position
        implausible = corrupt = False
        events: Sequence[tuple[bool, str]] = ()
        watch = self.frames
        # once per image received (an event-driven TPDO may arrive a cycle late, 000 Table 15)
        if image != watch.image:
            seen = watch.evaluate(image)
            if seen is not None:
                before, after = seen
                if after is not before:  # most frames: CLEAN after CLEAN, nothing changed
                    events = [(True, text) for text in edges(before, after)]
                if after is not CLEAN and after.corrupt:
                    corrupt = True
                    counters.frame_errors += 1
                    text = watch.failures.failed(t_sync, after)
                    if text:
                        events = [*events, (False, text)]
        counters.frame = watch.verdict if watch.checked else None
        if sample_time <= self.para1_since:
            position = velocity = math.nan  # latched while REG_PARA1 changed
        elif corrupt:
            position, velocity = self.position, estimator.velocity  # keep the last good ones
        elif image[7] & NOT_MEASURING:
            estimator.reset()  # REG_SSI_POS is frozen: the speed is unknown, restarts after
            velocity = math.nan
        elif sample_time >= t_sync:  # fresh
            velocity = estimator.update(sample_time, reg_ssi_pos)
            implausible = estimator.last_implausible
            if implausible:
                counters.implausible += 1
        elif counters.consecutive_stale >= self.stale_cycles:
            estimator.reset()  # the position is frozen: the speed is unknown
            velocity = math.nan
        else:
            velocity = estimator.velocity
        self._implausible = implausible
        self.position = position
        return JointOutput(position, velocity, events)


__all__ = ["ERRORS", "Joint", "JointOutput", "NOT_MEASURING", "encoder_layout", "joint_scale",
           "spec_max_speed"]
