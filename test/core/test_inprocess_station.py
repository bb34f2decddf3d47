"""Stations in process: the shipped two-encoder params file, and the accuracy of position and
velocity against the simulated ground truth (docs/node.md), through the node's own message
building (test/support/inprocess.py). Moved from test/ros/test_node_station.py
(docs/testing.md); the node keeps two bridges side by side in namespaces.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticStatus as D

from ssi_bridge.protocol.settings import load_params_file

REPO = Path(__file__).resolve().parents[2]
RATE = 100.0
STEP = 2 * math.pi / 8192  # rad per count of the default 13-bit single-turn resolution


def _collect(b, seconds: float) -> list:
    """joint_states of ``seconds`` of cycles, after the first few."""
    b.run_until(lambda: len(b.joint_state_msgs()) > 3, 10.0, "joint_states")
    start = len(b.joint_state_msgs())
    time.sleep(seconds)
    return b.joint_state_msgs()[start:]


def _times(msgs):
    return np.array([m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in msgs])


def test_shipped_two_encoder_station(inprocess):
    with open(REPO / "config" / "ssi_bridge.yaml") as f:
        b = inprocess(load_params_file(f))
    collected = _collect(b, 2.0)
    assert all(m.header.frame_id == "station" for m in collected)
    # a joint the cycle sets aside is left out of that cycle's message (docs/node.md "The
    # cycle"): a loaded machine starves the in-process station now and then, so a message
    # may carry one of the two joints, in the configured order, never another or none
    both = ["shoulder", "carriage"]
    assert all(m.name in (both, ["shoulder"], ["carriage"]) for m in collected), \
        {tuple(m.name) for m in collected}
    msgs = [m for m in collected if m.name == both]
    assert len(msgs) >= 0.8 * len(collected), f"{len(msgs)} of {len(collected)} carry both"
    t = _times(msgs)
    shoulder = np.array([m.position[0] for m in msgs])
    carriage = np.array([m.position[1] for m in msgs])
    # shoulder: AFM60 in Gray code, sine of 0.25 rev at 0.2 Hz about 1 rev -> 2pi +- pi/2 rad
    assert np.all(np.abs(shoulder - 2 * math.pi) <= math.pi / 2 + 1e-3), shoulder
    # carriage: TTK70 linear at 0.01 m/s -> metres, growing at that speed
    slope = np.polyfit(t - t[0], carriage, 1)[0]
    assert slope == pytest.approx(0.01, rel=0.02), f"carriage moves at {slope} m/s"
    assert np.all(np.abs(np.array([m.velocity[1] for m in msgs]) - 0.01) < 0.001)
    # every status OK (a loaded machine may hold a cycle back: awaited, not the first taken)
    b.run_until(lambda: b.level("shoulder") == D.OK and b.level("carriage") == D.OK
                and b.bus_status().level == D.OK, 10.0, "shoulder, carriage and bus OK")


def test_constant_speed_velocity_is_exact_to_quantisation(inprocess):
    b = inprocess({"publish_rate": RATE, "joint1.motion.velocity": 0.3})
    msgs = _collect(b, 2.0)
    v = np.array([m.velocity[0] for m in msgs])
    truth = 2 * math.pi * 0.3
    # bound: one count over the window of 4 periods, plus SYNC-stamp timing noise (docs/node.md)
    bound = STEP / (4 / RATE) + 0.01 * truth
    assert np.max(np.abs(v - truth)) <= bound, f"max error {np.max(np.abs(v - truth)):.4f} > {bound:.4f}"


def test_sine_velocity_error_stays_within_the_documented_lag_bound(inprocess):
    amp_rev, freq = 0.25, 0.5
    b = inprocess({"publish_rate": RATE, "joint1.motion.kind": "sine", "joint1.motion.start": 1.0,
                   "joint1.motion.amplitude": amp_rev, "joint1.motion.frequency": freq})
    msgs = _collect(b, 3.0)
    t = _times(msgs)
    t = t - t[0]
    p = np.array([m.position[0] for m in msgs])
    v = np.array([m.velocity[0] for m in msgs])
    w = 2 * math.pi * freq
    # ground truth: p = a sin wt + b cos wt + c (c = the 1 rev start), fitted
    basis = np.column_stack([np.sin(w * t), np.cos(w * t), np.ones_like(t)])
    (a, bc, _c), *_ = np.linalg.lstsq(basis, p, rcond=None)
    amp = 2 * math.pi * amp_rev
    assert math.hypot(a, bc) == pytest.approx(amp, rel=0.01), "position follows the sine"
    truth = w * (a * np.cos(w * t) - bc * np.sin(w * t))
    # documented bound (docs/node.md): the estimate is the mean speed over the window, i.e. the
    # speed at some instant inside it, so |error| <= a_max * span + 1 count / span, where span
    # is the time the window covers (window - 1 = 4 periods unless cycles were skipped);
    # a_max = A w^2 for a sine; 2 % of the peak speed covers stamp noise
    span = np.full_like(t, 4 / RATE)
    span[4:] = t[4:] - t[:-4]
    bound = amp * w * w * span + STEP / span + 0.02 * amp * w
    err = np.abs(v - truth)
    worst = int(np.argmax(err[4:] - bound[4:])) + 4
    assert np.all(err[4:] <= bound[4:]), (
        f"velocity error {err[worst]:.4f} rad/s > bound {bound[worst]:.4f} at sample {worst}")


def test_eight_encoders_at_the_highest_wire_rate_never_report_a_false_wire_break(inprocess):
    # The module latches when the SYNC is on the wire; a gateway thread that falls behind must
    # not clock two bursts inside one monoflop time (that reads as a missing start level,
    # ERR_SSI, 000 "Error detection / messages"). Regression: this flapped at 1 kHz.
    joints = [f"axis{i}" for i in range(1, 9)]
    # 8 slots fit the wire at 480 Hz at 1 Mbit/s (docs/canopen.md rate table), not at 1 kHz
    b = inprocess({"joints": joints, "publish_rate": 480.0, "bus.bitrate": 1_000_000})
    time.sleep(2.0)
    for name in joints:
        counters = b.joints[name].counters
        assert counters.error_cycles == 0, f"{name}: {b.status(name).message}"
        assert counters.samples > 50, name
