"""Every published sample is true at its stamp: the node under disturbance, held to the truth.

The node's one promise (docs/node.md, "Which cycle a TPDO answers"): each ``joint_states``
position is the encoder's position at ``header.stamp`` within one count plus the bound the node
states (``latch_bound_s`` on the bus status), and each finite velocity is within docs/node.md's
velocity bound. For a simulated encoder the true motion is known: the truth oracle
(``test/support/truth.py``) takes the node's parameters and the station's motion epoch (object
0x4004, read over ``~/sdo_read``) and holds every published sample against it. Each case
disturbs the bus the way real buses are disturbed, and checks the rule with no exception, that
the disturbance shows in the same cycle's ``~/status`` and in ``/diagnostics``, and that the
joint is published again afterwards. What needs no node process (one stray SYNC, a slow
foreign SYNC producer, CAN frame loss, REG_OFFSET written during motion) runs in process:
test/core/test_inprocess_truth.py (docs/testing.md).
"""

from __future__ import annotations

import os
import signal
import threading
import time

import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState
from sensor_msgs.msg import JointState
from ssi_bridge_msgs.srv import SetPreset

from support.node_changes import Change, hold_changes, set_integer, timed
from support.node_truth import K, Run, bus_values, epochs, foreign_syncs, params, station_pid
from support.truth import TruthOracle

from .conftest import inject, station_channel

@pytest.fixture
def channel(domain_id: int) -> str:
    """The node's bus.channel."""
    return f"truth_{domain_id}_{os.getpid()}"


@pytest.fixture
def wire(channel: str, domain_id: int) -> str:
    """The udp_multicast channel the node shares with its station: where another producer
    puts its frames."""
    return station_channel(channel, domain_id)


@pytest.mark.parametrize("seconds, queueing", [(0.5, False), (2.0, False), (1.0, True)],
                         ids=["stall_0.5s", "stall_2s", "queue_backlog_stall_1s"])
def test_a_stalled_station_never_publishes_an_old_latch(running, probe, channel, seconds,
                                                        queueing):
    """The station process is paused (SIGSTOP) and resumed: its controller kept a few frames,
    it handles them late and answers; no answer is published under a stamp it was not
    latched at, the stall shows, and the joint is published again.

    ``queueing``: a device that queues every SYNC (fault QUEUE_BACKLOG) answers a 1 s stall's
    backlog in a burst, each answer latched at its own SYNC: a surplus in the windows, set
    aside until it is in step. (A test function of its own before, on the same node.)"""
    run = Run(running, probe, params(channel))
    if queueing:
        inject(probe, run.node, kind=K.QUEUE_BACKLOG)
    time.sleep(0.5)
    station = station_pid(run.node)
    t0, w0 = time.monotonic(), time.time()
    os.kill(station, signal.SIGSTOP)
    try:
        time.sleep(seconds)
    finally:
        os.kill(station, signal.SIGCONT)
    t1, w1 = time.monotonic(), time.time()
    run.published_again(t1 + 0.5)
    time.sleep(1.0)
    run.check(f"queue_backlog_stall_{seconds:g}s" if queueing else f"stall_{seconds:g}s", t0)
    if queueing:
        reasons = run.set_aside_during(w1 - 1.0, w1 + 1.0)
        assert reasons, "the backlog's cycles are set aside"
    else:
        assert run.set_aside_during(w0, w1) & {"no answer"}, "~/status says why during the stall"
        after = run.diagnostics_after(t0)
        assert after is not None and after <= 0.2, \
            f"/diagnostics said so {after} s after the cycle"
        assert run.worst_level_during(t0, t1 + 0.5) > DiagnosticStatus.OK


# 10 Hz: test/core/test_inprocess_truth.py; 1000 Hz here, for /diagnostics within 0.2 s
@pytest.mark.parametrize("rate,seconds", [(1000.0, 2.0)])
def test_a_second_sync_producer_never_publishes_a_foreign_latch(running, probe, channel, wire,
                                                                rate, seconds):
    """Another producer's SYNCs (CiA 301 allows one producer): the station answers them too,
    each answer latched at that SYNC. None is published as the master's cycle; the bus says
    so; the joint is published again once they stop."""
    run = Run(running, probe, params(channel))
    stop = threading.Event()
    t0 = time.monotonic()
    run.phase(f"foreign SYNC {rate:g} Hz")
    try:
        sent = foreign_syncs(wire, rate, seconds, stop)
    finally:
        stop.set()
    t1 = time.monotonic()
    assert sent >= 0.1 * rate * seconds  # a test process starved beside burners sends fewer
    run.published_again(t1 + 0.5)
    time.sleep(0.5)
    run.check(f"foreign_sync_{rate:g}hz", t0)
    if rate >= 1000:  # the flood leaves the joint out: /diagnostics says so within 0.2 s
        after = run.diagnostics_after(t0)
        assert after is not None and after <= 0.2, f"/diagnostics {after} s after the cycle"
    probe.wait_for(lambda: int(bus_values(run.diags).get("foreign_syncs", "0")) > 0, 5.0,
                   "foreign_syncs counted", run.node)
    warned = [st.message for t, arr in run.diags if t0 <= t <= t1 + 1.0 for st in arr.status
              if st.name == "/ssi_bridge: bus" and st.level >= DiagnosticStatus.WARN]
    assert any("another producer" in m for m in warned), warned[-3:]


PARA1_LSB1 = 0x19010100  # 000 Table 19: the default frame with INVALID_BITS_LSB = 1


def test_reg_para1_and_a_preset_written_during_motion_move_the_truth_at_the_call(
        running, probe, channel):
    """REG_PARA1 (the ``joint1.para1`` parameter: INVALID_BITS_LSB 0 -> 1, half the counts
    per turn) and a preset (``~/set_preset``: REG_OFFSET = encoder - target, 000 "Offset
    function"; the answer names the REG_OFFSET written) while the shaft turns: each moves
    the truth when the module takes it. The samples stamped before a call hold the rule
    against the settings before it, those stamped after it returned against the new ones,
    those stamped during it against either (or NaN)."""
    p = params(channel)
    run = Run(running, probe, p)
    time.sleep(0.5)
    t0 = time.monotonic()
    epoch = epochs(probe, run.node, [1])
    lsb1 = {**p, "joint1.para1": PARA1_LSB1}
    para1, _ = timed(run, "joint1.para1 := 0x19010100",
                     lambda: set_integer(probe, run.node, "joint1.para1", PARA1_LSB1),
                     lambda _r: TruthOracle.from_params(lsb1, epoch))
    time.sleep(0.5)
    preset, res = timed(run, "~/set_preset 1.0 rad", lambda: probe.call(
        SetPreset, run.node.topic("~/set_preset"),
        SetPreset.Request(joint="joint1", position=1.0), timeout=30.0),
        lambda r: TruthOracle.from_params(lsb1, epoch, offsets={"joint1": r.offset}))
    assert res.success, res.message
    time.sleep(0.5)
    hold_changes(run, [para1, preset], "para1_and_preset_during_motion", t0)


def test_deactivate_publishes_nothing_and_activate_publishes_the_truth_again(
        running, probe, channel):
    """A lifecycle manager deactivates the node (``~/change_state``) and activates it again:
    nothing is stamped or published while it is inactive, and every sample after the
    activation holds the rule (against the station's epoch read again after it)."""
    run = Run(running, probe, params(channel))
    sent = probe.subscribe_sent(JointState, run.node.topic("joint_states"), qos=2000)
    time.sleep(0.5)
    t0 = time.monotonic()

    def change(transition: int) -> None:
        assert probe.call(ChangeState, run.node.topic("~/change_state"), ChangeState.Request(
            transition=Transition(id=transition)), timeout=30.0).success, run.node.log()[-2000:]

    run.phase("deactivate")
    w0 = time.time()
    change(Transition.TRANSITION_DEACTIVATE)
    w_off = time.time()
    time.sleep(1.0)
    w_on = time.time()
    run.phase("activate")
    change(Transition.TRANSITION_ACTIVATE)
    w1 = time.time()
    run.published_again(time.monotonic())
    time.sleep(1.0)
    cycle = Change("deactivate .. activate", w0, w1,
                   TruthOracle.from_params(run.params, epochs(probe, run.node, [1])))
    run.received_until(time.time())
    stamped = [s.stamp for s in run.samples() if w_off < s.stamp < w_on]
    assert not stamped, f"{len(stamped)} samples stamped while inactive, e.g. {stamped[:3]}"
    # by the time the node sent each (its DDS source timestamp), not when this probe got it:
    # a busy probe receives seconds late what the node sent before the deactivation
    published = [t for t, _ in sent if w_off < t < w_on]
    assert any(t < w_off for t, _ in sent) and any(t > w_on for t, _ in sent), "send times"
    assert not published, f"{len(published)} joint_states published while inactive"
    hold_changes(run, [cycle], "lifecycle_deactivate_activate", t0)
