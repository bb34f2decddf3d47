"""The disturbance matrix's long cases: one node through many disturbances, held to the truth.

The slow tier (``make test-slow``; ``test/conftest.py`` lists them): the shipped two-station
example (rotary and linear, constant and sine) beside two CPU burners, eight joints on one
station, and a standalone station killed and another started on the same bus. Every
published sample is checked against the truth oracle as in ``test_node_truth.py``; a
violation names the disturbance it fell in.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest
import yaml

from support.node_changes import Change, hold_changes, published, read_burst
from support.node_truth import RATE, Run, eight_joints, epochs, matrix, params, two_stations
from support.truth import TruthOracle

from .conftest import installed_executable, station_channel


@pytest.fixture
def channel(domain_id: int) -> str:
    """The node's bus.channel."""
    return f"matrix_{domain_id}_{os.getpid()}"


@pytest.fixture
def wire(channel: str, domain_id: int) -> str:
    """The udp_multicast channel the node shares with its station."""
    return station_channel(channel, domain_id)


def test_the_disturbance_matrix_on_two_stations_beside_two_burners(running, probe, channel,
                                                                   wire):
    """Rotary and linear, constant and sine, two stations; two CPU burners throughout."""
    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    try:
        run = Run(running, probe, two_stations(channel))
        t0 = time.monotonic()
        matrix(run, wire, 1)
        run.check("matrix_two_stations_burners", t0)
    finally:
        for p in burners:
            os.kill(p.pid, signal.SIGKILL)
            p.wait(5)


def test_the_disturbance_matrix_on_eight_joints(running, probe, channel, wire):
    run = Run(running, probe, eight_joints(channel))
    t0 = time.monotonic()
    matrix(run, wire, 1)
    run.check("matrix_eight_joints", t0)


def test_a_station_killed_and_started_again_on_the_same_bus(start_node, probe, tmp_path,
                                                           domain_id):
    """A real-station set-up (simulation.enabled false): the standalone ``station`` program
    killed and another started on the same bus; its motion epoch is new."""
    channel = station_channel(f"restart_{domain_id}_{os.getpid()}", domain_id)
    params = {"joints": ["joint1"], "publish_rate": RATE, "diagnostics_period": 0.25,
              "simulation.enabled": False, "bus.interface": "udp_multicast",
              "bus.channel": channel}
    config = tmp_path / "station.yaml"
    config.write_text(yaml.safe_dump({"/**": {"ros__parameters": {"joints": ["joint1"]}}}))

    def station() -> subprocess.Popen:
        proc = subprocess.Popen(
            [str(installed_executable("station")), "--params-file", str(config),
             "--interface", "udp_multicast", "--channel", channel],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        time.sleep(2.0)
        return proc

    first = station()
    second = None
    try:
        run = Run(lambda p: start_node(p), probe, params)
        time.sleep(0.5)
        t0 = time.monotonic()
        os.kill(first.pid, signal.SIGKILL)
        first.wait(5)
        cut = time.time()  # wire time: the stamps after it are the new station's
        time.sleep(0.5)
        second = station()
        run.published_again(time.monotonic() + 0.5)
        time.sleep(1.0)
        # the samples stamped before the kill against the first station's epoch, after it
        # against the new one's: split by stamp once the probe has every sample stamped so
        # far (hold_changes), never by cutting the probe's live list, which goes on
        # receiving the new station's samples while a check waits for them
        restart = Change("the station killed and another started", cut, cut,
                         TruthOracle.from_params(params, epochs(probe, run.node, [1])))
        hold_changes(run, [restart], "station_restart", t0)
    finally:
        for proc in (first, second):
            if proc is not None and proc.poll() is None:
                os.kill(proc.pid, signal.SIGKILL)
                proc.wait(5)


def test_a_burst_of_1000_service_calls_during_motion(running, probe, channel):
    """1000 ``~/read_register`` calls sent at once from four clients: the node queues up to
    100 and answers the rest "busy" (docs/node.md "Services"); every call is answered,
    joint_states keeps coming at the rate it had before the burst (by the node's own count
    on ~/status: a loaded machine may hold it below 200 Hz whatever the services do), and
    every sample holds the rule."""
    run = Run(running, probe, params(channel))
    w_base = time.time()
    time.sleep(2.0)
    t0, w0 = time.monotonic(), time.time()
    run.phase("1000 ~/read_register calls")
    outcomes, took = read_burst(probe, run.node, 1000, 4, timeout=120.0, joint="joint1")
    w1 = time.time()
    time.sleep(0.5)
    base_rate, base_gap = published(run, w_base, w0)
    rate, gap = published(run, w0, w1)
    print(f"burst: {dict(outcomes)} in {took:.2f} s; published {rate:.0f}/s, longest gap "
          f"received {gap * 1e3:.1f} ms (before: {base_rate:.0f}/s, {base_gap * 1e3:.1f} ms)")
    run.check("service_burst_1000", t0)
    assert outcomes["unanswered"] == 0, outcomes
    assert outcomes["ok"] > 0 and set(outcomes) <= {"ok", "busy", "unanswered"}, outcomes
    assert rate >= 0.8 * base_rate, (f"joint1 published at {rate:.0f}/s during the burst, "
                                     f"{base_rate:.0f}/s before")
