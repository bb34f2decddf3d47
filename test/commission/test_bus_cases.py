"""The command line on buses that are not tidy: two stations against the clock, another
master, garbage, a device of another kind, modules with no working encoder.

``commission`` runs in this process through its ``main`` (the installed executable is
exercised by test/ros/test_node_from_commissioned_file.py); the stations are simulated ones
it is not told about.
Exit codes are the documented ones (ssi_bridge/tools/commission.py): 0 done, 3 another master.
"""

from __future__ import annotations

import json
import logging
import random
import threading
import time
import time
from collections.abc import Iterator

import can
import canopen
import pytest

from ssi_bridge.base.buses import open_python_can
from ssi_bridge.client.master import BridgeClient
from ssi_bridge.protocol.dictionary import SYNC_COB_ID
from ssi_bridge.protocol.para1 import Para1
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.sim.gateway.simulation import FaultKind
from ssi_bridge.tools.commission import EXIT_OK, EXIT_OTHER_MASTER, main

from .conftest import true_joint


def _cli(channel: str, *extra: str) -> list[str]:
    return ["--interface", "udp_multicast", "--channel", channel, *extra]


class Sender:
    """A thread putting frames on the bus every ``period`` s until stopped."""

    def __init__(self, channel: str, frames: list[can.Message], period: float) -> None:
        self.bus = open_python_can(BusConfig("udp_multicast", channel))
        self.frames, self.period = frames, period
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while not self.stop.wait(self.period):
            for frame in self.frames:
                self.bus.send(frame)

    def close(self) -> None:
        self.stop.set()
        self.thread.join(2)
        self.bus.shutdown()


@pytest.fixture(autouse=True)
def library_log_levels() -> Iterator[None]:
    """``main`` quiets canopen's and python-can's loggers for the process, as the executable
    should; here the process is the test worker's, so their levels are set back after each
    test (else a later test on the worker, e.g. test/client/test_silent_gateway_log.py, sees
    no canopen line at all)."""
    levels = {name: logging.getLogger(name).level for name in ("canopen", "can")}
    yield
    for name, level in levels.items():
        logging.getLogger(name).setLevel(level)


@pytest.fixture
def senders() -> Iterator[list[Sender]]:
    made: list[Sender] = []
    yield made
    for sender in made:
        sender.close()


def test_two_stations_with_four_joints_in_ten_seconds_with_a_progress_line(
        stations, bus_channel, capsys):
    rng = random.Random(7)
    layout = {12: [true_joint(rng, 12, 1, "AFM60_MULTI", {"steps_per_rev": 32768}),
                   true_joint(rng, 12, 2, "TTK70", {})],
              40: [true_joint(rng, 40, 1, "AHM36_MULTI", {}),
                   true_joint(rng, 40, 3, "ARS60", {})]}
    stations(layout)
    start = time.monotonic()
    code = main(_cli(bus_channel, "--seconds", "3", "--dry-run"))
    took = time.monotonic() - start
    out, err = capsys.readouterr()
    assert code == EXIT_OK, err
    assert took <= 10.0, f"scan + 3 s of sampling took {took:.1f} s"
    assert "SDO scan of node ids 1-127" in err and "sampling" in err, err
    assert "joints: [node12_slot1, node12_slot2, node40_slot1, node40_slot3]" in out, out
    assert "stations: [12, 40]" in out


def test_another_master_is_refused_in_one_line(stations, bus_channel, senders, capsys):
    rng = random.Random(8)
    stations({5: [true_joint(rng, 5, 1, "GENERIC", {})]})
    senders.append(Sender(bus_channel, [can.Message(arbitration_id=SYNC_COB_ID,
                                                    is_extended_id=False)], 0.01))
    code = main(_cli(bus_channel, "--seconds", "1", "-o", "never.yaml"))
    out, err = capsys.readouterr()
    assert code == EXIT_OTHER_MASTER
    last = err.strip().splitlines()[-1]
    assert last.startswith("commission: another CANopen master is active") and "SYNC" in last
    assert "--listen-only" in last and out == ""
    assert "SDO scan" not in err  # nothing was sent


def test_listen_only_watches_a_running_master_and_sends_nothing(stations, bus_channel,
                                                               capsys):
    rng = random.Random(9)
    joint = true_joint(rng, 6, 1, "AHM36_MULTI", {})
    stations({6: [joint]})
    master = BridgeClient(BusConfig("udp_multicast", bus_channel), 6, 1)
    master.connect()
    master.edit_output(1, lambda out: out.__setitem__(4, 33))  # idle read: REG_SSI_FRAME
    watch = open_python_can(BusConfig("udp_multicast", bus_channel))
    stop = threading.Event()

    def drive() -> None:
        while not stop.wait(0.02):
            master.sync()

    driver = threading.Thread(target=drive, daemon=True)
    driver.start()
    try:
        code = main(_cli(bus_channel, "--listen-only", "--seconds", "2", "--json"))
    finally:
        stop.set()
        driver.join(2)
        master.close()
    closed = time.time()  # the watch's frames carry their kernel receive time (wall clock)
    sent_by_others = []
    # what came until the master closed; the station's heartbeats go on after it, often
    # enough that a read until the bus is quiet for 0.05 s may never end
    while (msg := watch.recv(0.05)) is not None and msg.timestamp <= closed:
        sent_by_others.append(msg.arbitration_id)
    watch.shutdown()
    out, err = capsys.readouterr()
    assert code == EXIT_OK, err
    report = json.loads(out)
    assert report["listen_only"] and "6" in report["heartbeats"]
    seen = report["observed"]["6/1"]
    assert seen["state"] == "moving" and seen["code"] == joint.settings.code
    assert seen["direction"] == joint.direction
    assert report["gateways"] == [] and "SDO scan" not in err
    # while it watched, nobody asked the station anything: the running master had finished
    # its set-up, and the tool sent nothing (no SDO request 0x600 + id, no NMT command)
    assert sent_by_others and not [c for c in sent_by_others
                                   if c == 0x000 or 0x600 < c <= 0x67F], sent_by_others


def _other_device(channel: str, node_id: int) -> canopen.Network:
    """A CANopen device that is no XN-GW-CANOPEN: canopen's LocalNode with its own identity."""
    od = canopen.ObjectDictionary()
    for index, name, data_type, value in ((0x1000, "Device type", canopen.objectdictionary.UNSIGNED32,
                                           0x0002_0192),
                                          (0x1008, "Manufacturer device name",
                                           canopen.objectdictionary.VISIBLE_STRING, "ACME-IO")):
        var = canopen.objectdictionary.ODVariable(name, index, 0)
        var.data_type, var.access_type, var.default = data_type, "ro", value
        od.add_object(var)
    network = canopen.Network(open_python_can(BusConfig("udp_multicast", channel)))
    network.connect()
    network.add_node(canopen.LocalNode(node_id, od))
    return network


def test_garbage_a_foreign_device_and_slots_without_a_working_encoder_are_reported(
        stations, bus_channel, senders, capsys):
    rng = random.Random(10)
    good = true_joint(rng, 20, 1, "AHM36_MULTI", {})
    broken = true_joint(rng, 20, 3, "AFS60", {})       # slot 2: a module with nothing on it
    truth = stations({20: [good, broken]})
    truth.stations[20].control.command(FaultKind.DATA_WIRE_BREAK, 3)
    other = _other_device(bus_channel, 33)
    senders.append(Sender(bus_channel, [
        can.Message(arbitration_id=0x1ABCDEF, is_extended_id=True, data=b"\x01\x02"),
        can.Message(arbitration_id=0x77E, is_extended_id=False, data=b"\xff\xff\xff")], 0.05))
    try:
        code = main(_cli(bus_channel, "--seconds", "1.5", "--json", "--dry-run"))
    finally:
        other.disconnect()
    out, err = capsys.readouterr()
    assert code == EXIT_OK and "Traceback" not in err, err
    report = json.loads(out)
    assert [g["node_id"] for g in report["gateways"]] == [20]
    assert [(d["node_id"], "not an XN-GW-CANOPEN" in d["reason"])
            for d in report["other_devices"]] == [(33, True)]
    assert any(k.startswith("extended frame") for k in report["garbage"]), report["garbage"]
    assert any("malformed heartbeat on 0x77E" in k for k in report["garbage"])
    gateway = report["gateways"][0]
    assert [e["slot"] for e in gateway["empty_slots"]] == [4, 5, 6, 7, 8]
    assert all("0x06090011" in e["reason"] for e in gateway["empty_slots"])
    slots = {s["slot"]: s for s in gateway["slots"]}
    assert slots[1]["joint"] == "node20_slot1" and slots[1]["problem"] is None
    assert slots[2]["joint"] is None and "every frame is 0" in slots[2]["problem"]
    assert slots[3]["joint"] is None and "ERR_SSI" in slots[3]["problem"]
    assert slots[3]["diagnostics"]["err_ssi"] > 0.9
    assert slots[3]["diagnostics"]["now"] == ["Wire-break"]   # 000 Table 27, bit 1
    assert slots[1]["diagnostics"]["now"] == []
    assert "joints: [node20_slot1]" in report["params"]


def test_a_code_contradicting_para1_is_corrected_in_the_file_and_written_only_on_configure(
        stations, bus_channel, capsys):
    """000 Table 19: the frames are Gray but SSI_CODE_G/D says binary."""
    rng = random.Random(11)
    joint = true_joint(rng, 8, 1, "AHM36_MULTI", {})
    truth = stations({8: [joint]})
    module = truth.stations[8].sim.modules[0]
    binary = Para1(ssi_frame_len=27, ssi_bit_rate=2).encode()
    gray = Para1(ssi_frame_len=27, ssi_bit_rate=2, ssi_code_gray=True).encode()
    wrong, right = (binary, gray) if joint.settings.code == "gray" else (gray, binary)
    module.write_para1(wrong)
    assert main(_cli(bus_channel, "--seconds", "1", "--dry-run")) == EXIT_OK
    out, _ = capsys.readouterr()
    assert f"para1: 0x{right:08X}   # corrected from the 0x{wrong:08X} read" in out, out
    assert module.para1.encode() == wrong  # nothing written without --configure
    assert main(_cli(bus_channel, "--seconds", "1", "--configure")) == EXIT_OK
    out, _ = capsys.readouterr()
    assert f"REG_PARA1 0x{right:08X} written" in out, out
    assert module.para1.encode() == right
