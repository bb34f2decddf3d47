"""The truth oracle: where each simulated encoder really was at a published stamp.

A simulated station's encoders follow closed-form motion profiles on the station's model
clock, wire time minus its motion epoch (object 0x4004, docs/canopen.md). Given the node's
parameters (the dict of a params file: ``joints``, ``<joint>.family``, ``.slot``, ``.station``,
``.para1``, ``.direction``, ``.motion.*``, the resolution overrides, ``velocity_window``) and
that epoch, :class:`TruthOracle` says for any wire time what the node should publish for a
joint: REG_SSI_POS of the shaft at that instant (the simulator's own encoder, SSI line and
XN-1SSI module, cycled there: quantisation, code, frame length, invalid bits, REG_OFFSET)
through the node's own counts -> units scale (``core/joint.py``), and the true velocity. It
holds published samples against them:

* position: ``|residual| <= 1 count + max_speed_counts * latch_bound_s``, the residual in
  REG_SSI_POS counts, wrapped at the multiturn range (rotary);
* velocity (finite only; NaN is "unknown", never wrong): within docs/node.md's bound
  ``a_max * span + 1 count / span``, widened by the latch bound at both ends of the window
  (``2 * max_speed * latch_bound_s / span``) and the stamp resolution, for the window the node
  may have used: 2 to ``velocity_window`` of the joint's published samples (fewer after a
  restart), so the largest of those bounds.

The truth is the shaft at the stamp itself: an encoder that forms its value every 125-150 µs
(asynchronous SSI, 004 §3.1) reports one formed up to that much earlier, which is part of the
latch bound a caller states. Test-side only: the driver never imports it. No ROS: a list of
``(stamp_s, joint, position, velocity)`` is all it needs (:func:`samples_from_joint_states`
turns JointState messages, or tuples shaped like them, into that).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from ssi_bridge.core.joint import joint_scale
from ssi_bridge.core.joint_scale import JointScale
from ssi_bridge.protocol.encoder_config import Direction
from ssi_bridge.protocol.joint_encoder import count_factor, joint_config
from ssi_bridge.protocol.registers import Reg
from ssi_bridge.protocol.settings import JOINT_DEFAULTS, JointSettings, joint_from_values
from ssi_bridge.sim.encoder.encoder import SsiEncoder
from ssi_bridge.sim.gateway.station import make_motion
from ssi_bridge.sim.line.line import LineConfig, SsiLine
from ssi_bridge.sim.module.xn1ssi import Xn1Ssi

#: the node's default ``velocity_window``
DEFAULT_WINDOW = 5
#: resolution of a stamp (s): a double of CLOCK_REALTIME seconds (docs/node.md "Velocity")
STAMP_RESOLUTION_S = 1e-6
#: a module cycle this close after the previous one (or before it) runs on a fresh SSI line:
#: the line holds its word for the monoflop time after a burst (004 §2.2)
_FRESH_LINE_S = 1e-3


@dataclass(frozen=True)
class Sample:
    """One published (stamp, joint, position, velocity): joint units, NaN = unknown."""

    stamp: float
    joint: str
    position: float
    velocity: float


@dataclass(frozen=True)
class Violation:
    """A sample off the truth beyond its bound: ``kind`` "position" or "velocity"."""

    stamp: float
    joint: str
    kind: str
    #: position residual in counts (position violations), else 0
    residual_counts: float
    #: published - true velocity, joint units/s (velocity violations), else 0
    velocity_error: float
    #: the bound it broke (counts or units/s)
    bound: float


@dataclass
class TruthReport:
    """What :meth:`TruthOracle.check` found."""

    #: samples whose position was checked (finite)
    checked: int = 0
    #: samples published with a NaN position (unknown: nothing to check)
    unknown: int = 0
    #: velocities checked (finite)
    velocities_checked: int = 0
    #: largest |position residual| (counts)
    worst_residual_counts: float = 0.0
    #: largest |published - true velocity| (joint units/s)
    worst_velocity_error: float = 0.0
    #: largest |velocity error| / its bound
    worst_velocity_ratio: float = 0.0
    violations: list[Violation] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """True when no sample broke its bound."""
        return not self.violations

    def summary(self, first: int = 5) -> str:
        """One line of figures, and the first few violations."""
        text = (f"{self.checked} positions checked ({self.unknown} NaN), worst residual "
                f"{self.worst_residual_counts:.2f} counts; {self.velocities_checked} "
                f"velocities, worst error {self.worst_velocity_error:.4g} units/s "
                f"({self.worst_velocity_ratio:.2f} of its bound); "
                f"{len(self.violations)} violations")
        for v in self.violations[:first]:
            text += (f"\n  {v.kind} {v.joint} at {v.stamp:.6f}: residual "
                     f"{v.residual_counts:.1f} counts, velocity error {v.velocity_error:.4g} "
                     f"(bound {v.bound:.4g})")
        return text


def flatten(values: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested parameters as the node's dotted names: ``{"j": {"slot": 1}}`` ->
    ``{"j.slot": 1}``."""
    out: dict[str, Any] = {}
    for key, value in values.items():
        if isinstance(value, Mapping):
            out.update(flatten(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def joints_of(params: Mapping[str, Any]) -> tuple[JointSettings, ...]:
    """The joints the node makes of ``params`` (dotted or nested names), as the node
    assigns them: ``<joint>.station`` (0: the first of ``stations``, else ``bus.node_id``),
    ``<joint>.slot`` (0: the joint's place among its station's joints)."""
    values = flatten(params)
    names = [str(n) for n in values.get("joints", ["joint1"])]
    stations = [int(s) for s in values.get("stations", [0]) if int(s)] or \
        [int(values.get("bus.node_id", 1))]
    per_station: dict[int, int] = {}
    joints = []
    for name in names:
        jv = {key: values.get(f"{name}.{key}", default) for key, default in JOINT_DEFAULTS.items()}
        station = int(values.get(f"{name}.station", 0)) or stations[0]
        index = per_station[station] = per_station.get(station, 0) + 1
        joints.append(joint_from_values(name, jv, slot=int(jv["slot"]) or index,
                                        station=station))
    return tuple(joints)


class JointTruth:
    """One joint's truth: its simulated encoder, SSI line and module, and the node's scale.

    :param joint: the joint's settings
    :param epoch: the motion epoch of its station (wire time, s)
    :param reg_offset: REG_OFFSET of its module (a preset: ``~/set_preset`` writes it)
    """

    def __init__(self, joint: JointSettings, epoch: float, reg_offset: int = 0) -> None:
        self.joint = joint
        self.epoch = epoch
        self.reg_offset = reg_offset
        config = joint_config(joint)
        self.motion = make_motion(joint.motion)
        # formed at the instant asked for (no formation period): the shaft at the stamp
        self._config = dataclasses.replace(config, formation_period_s=0.0)
        #: the node's counts -> units scale for the joint's REG_PARA1
        self.scale: JointScale = joint_scale(joint, config, joint.para1)
        sign = 1 if config.direction is Direction.INCREASING else -1
        #: joint units per unit of the motion profile (rev or m), signed
        self.gain = (sign * config.steps_per_unit * count_factor(config, joint.para1)
                     * self.scale.unit_per_count)
        self._module: Xn1Ssi | None = None
        self._last = math.inf

    def _fresh_module(self) -> Xn1Ssi:
        encoder = SsiEncoder(self._config, self.motion)
        line = SsiLine(encoder, LineConfig(cable_length_m=self.joint.cable_length,
                                           check_cable_table=False))
        module = Xn1Ssi(line, slot=self.joint.slot)
        module.write_para1(self.joint.para1)
        module.write_register(Reg.REG_OFFSET, self.reg_offset & 0xFFFF_FFFF)
        return module

    def reg_ssi_pos(self, t: float) -> int:
        """REG_SSI_POS the module holds after a cycle latched at wire time ``t``."""
        tau = t - self.epoch
        if self._module is None or not self._last + _FRESH_LINE_S <= tau:
            self._module = self._fresh_module()
        self._module.cycle(tau)
        self._last = tau
        return self._module.ssi_pos

    def position(self, t: float) -> float:
        """The joint position the node publishes for a latch at wire time ``t``."""
        return self.scale.position(self.reg_ssi_pos(t))

    def velocity(self, t: float) -> float:
        """The shaft's true velocity at wire time ``t`` (joint units/s)."""
        return self.motion.velocity(t - self.epoch) * self.gain

    @property
    def counts_per_unit(self) -> float:
        """REG_SSI_POS counts per joint unit (rad or m)."""
        return 1.0 / abs(self.scale.unit_per_count)

    @property
    def max_speed(self) -> float:
        """The fastest the motion profile moves (joint units/s)."""
        m = self.joint.motion
        if m.kind == "still":
            return 0.0
        if m.kind == "sine":
            return abs(m.amplitude * 2.0 * math.pi * m.frequency * self.gain)
        return abs(m.velocity * self.gain)

    @property
    def max_acceleration(self) -> float:
        """The largest acceleration of the motion profile (joint units/s²)."""
        m = self.joint.motion
        if m.kind == "sine":
            return abs(m.amplitude * (2.0 * math.pi * m.frequency) ** 2 * self.gain)
        return 0.0

    def residual(self, t: float, position: float) -> float:
        """``position`` published for stamp ``t`` minus the truth, in counts (rotary: wrapped
        into +- half the multiturn range)."""
        counts = (position - self.position(t)) / abs(self.scale.unit_per_count)
        modulus = self.scale.modulus
        if modulus:
            counts = (counts + modulus / 2.0) % modulus - modulus / 2.0
        return counts


class TruthOracle:
    """The truth of every joint of a node's simulated station(s) (see the module doc).

    :param joints: the node's joints
    :param epochs: motion epoch (wire time, s) per station node id
    :param offsets: REG_OFFSET per joint (default 0: no preset)
    :param velocity_window: the node's ``velocity_window``
    """

    def __init__(self, joints: Iterable[JointSettings], epochs: Mapping[int, float],
                 offsets: Mapping[str, int] | None = None,
                 velocity_window: int = DEFAULT_WINDOW) -> None:
        offsets = offsets or {}
        self.joints: dict[str, JointTruth] = {}
        for joint in joints:
            if joint.station not in epochs:
                raise KeyError(f"no motion epoch for station {joint.station} of {joint.name}")
            self.joints[joint.name] = JointTruth(joint, epochs[joint.station],
                                                 offsets.get(joint.name, 0))
        self.velocity_window = velocity_window

    @classmethod
    def from_params(cls, params: Mapping[str, Any], epoch: float | Mapping[int, float],
                    offsets: Mapping[str, int] | None = None) -> TruthOracle:
        """The oracle of a node run with ``params`` (a params file's dict); ``epoch``: the
        station's motion epoch (object 0x4004 / 1e6), or one per station node id."""
        joints = joints_of(params)
        epochs = (dict(epoch) if isinstance(epoch, Mapping)
                  else {j.station: float(epoch) for j in joints})
        window = int(flatten(params).get("velocity_window", DEFAULT_WINDOW))
        return cls(joints, epochs, offsets, window)

    def _joint(self, joint: str) -> JointTruth:
        try:
            return self.joints[joint]
        except KeyError:
            raise KeyError(f"unknown joint {joint!r}; joints: {', '.join(self.joints)}") \
                from None

    def position(self, joint: str, t: float) -> float:
        """Where the node should publish ``joint`` for a latch at wire time ``t`` (units)."""
        return self._joint(joint).position(t)

    def velocity(self, joint: str, t: float) -> float:
        """The true velocity of ``joint`` at wire time ``t`` (units/s)."""
        return self._joint(joint).velocity(t)

    def counts_per_unit(self, joint: str) -> float:
        """REG_SSI_POS counts per joint unit."""
        return self._joint(joint).counts_per_unit

    def max_speed(self, joint: str) -> float:
        """The fastest ``joint``'s motion profile moves (units/s)."""
        return self._joint(joint).max_speed

    def residual(self, joint: str, stamp: float, position: float) -> float:
        """Published minus true position of ``joint`` at ``stamp``, in counts."""
        return self._joint(joint).residual(stamp, position)

    def position_bound(self, joint: str, latch_bound_s: float) -> float:
        """The largest residual (counts) the rule allows: 1 + max speed x latch bound."""
        truth = self._joint(joint)
        return 1.0 + truth.max_speed * truth.counts_per_unit * latch_bound_s

    def check(self, samples: Iterable[Sample], latch_bound_s: float = 0.0) -> TruthReport:
        """Hold ``samples`` (any order) against the truth; see the module doc for the rule."""
        report = TruthReport()
        by_joint: dict[str, list[Sample]] = {}
        for sample in samples:
            by_joint.setdefault(sample.joint, []).append(sample)
        for name, series in by_joint.items():
            truth = self._joint(name)
            series.sort(key=lambda s: s.stamp)
            self._check_positions(truth, series, latch_bound_s, report)
            self._check_velocities(truth, series, latch_bound_s, report)
        return report

    def _check_positions(self, truth: JointTruth, series: list[Sample], latch_bound_s: float,
                         report: TruthReport) -> None:
        bound = self.position_bound(truth.joint.name, latch_bound_s)
        for s in series:
            if not math.isfinite(s.position):
                report.unknown += 1
                continue
            report.checked += 1
            r = truth.residual(s.stamp, s.position)
            report.worst_residual_counts = max(report.worst_residual_counts, abs(r))
            if abs(r) > bound:
                report.violations.append(Violation(s.stamp, s.joint, "position", r, 0.0, bound))

    def velocity_bound(self, truth: JointTruth, span: float, latch_bound_s: float) -> float:
        """docs/node.md's bound for a window of ``span`` s, widened by the latch bound."""
        unit = abs(truth.scale.unit_per_count)
        return (truth.max_acceleration * span + unit / span
                + 2.0 * truth.max_speed * (latch_bound_s + STAMP_RESOLUTION_S) / span)

    def _check_velocities(self, truth: JointTruth, series: list[Sample], latch_bound_s: float,
                          report: TruthReport) -> None:
        # the estimate spans 2..N of the joint's last published samples (fewer after a
        # restart, which the samples do not always show): the bound a*span + c/span is
        # convex in span, so its largest value over those windows is at the shortest or the
        # longest; a velocity within the larger of the two is within its window's bound
        window = self.velocity_window
        known = [s for s in series if math.isfinite(s.position)]
        for k, s in enumerate(known):
            if k == 0 or not math.isfinite(s.velocity):
                continue
            shortest = s.stamp - known[k - 1].stamp
            longest = s.stamp - known[max(0, k - (window - 1))].stamp
            if shortest <= 0:
                continue
            report.velocities_checked += 1
            error = s.velocity - truth.velocity(s.stamp)
            bound = max(self.velocity_bound(truth, shortest, latch_bound_s),
                        self.velocity_bound(truth, longest, latch_bound_s))
            report.worst_velocity_error = max(report.worst_velocity_error, abs(error))
            report.worst_velocity_ratio = max(report.worst_velocity_ratio, abs(error) / bound)
            if abs(error) > bound:
                report.violations.append(Violation(s.stamp, s.joint, "velocity", 0.0, error,
                                                   bound))


def samples_from_joint_states(messages: Iterable[Any]) -> list[Sample]:
    """Samples of JointState messages (``header.stamp.sec/nanosec``, ``name``, ``position``,
    ``velocity``) or of tuples ``(stamp_s, names, positions, velocities)``; a missing
    velocity is NaN. Nothing ROS is imported: messages are read by their fields."""
    out: list[Sample] = []
    for msg in messages:
        if isinstance(msg, tuple):
            stamp, names, positions, velocities = msg
        else:
            st = msg.header.stamp
            stamp = st.sec + st.nanosec * 1e-9
            names, positions, velocities = msg.name, msg.position, msg.velocity
        for i, name in enumerate(names):
            velocity = velocities[i] if i < len(velocities) else math.nan
            out.append(Sample(float(stamp), str(name), float(positions[i]), float(velocity)))
    return out


__all__ = ["JointTruth", "Sample", "TruthOracle", "TruthReport", "Violation", "joints_of",
           "samples_from_joint_states"]
