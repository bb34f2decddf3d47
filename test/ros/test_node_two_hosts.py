"""Two hosts: the station on one "machine", the node on another, a subscriber on a third.

Three network namespaces stand for the machines: the station's and the node's joined by a veth
pair (the CAN bus: python-can's udp_multicast on 10.201.0.0/30), the node's and the
subscriber's by a second pair (DDS on 10.201.0.4/30; the subscriber sits in a namespace of
its own so joint_states and the services really cross a network, not shared memory: Fast DDS
runs UDPv4 only here). The test creates the namespaces and always removes them; traffic
stays inside them (ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET in this test only). Skipped with the
reason where ``ip netns`` is not permitted.
"""

from __future__ import annotations

import json
import os
import shutil
import statistics
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from support.stations import stop_station

from .conftest import dds_env, installed_executable

SUBSCRIBER = Path(__file__).with_name("netns_subscriber.py")
RATE = 50.0
REG_LOWER_LIMIT = 48


def _ip(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True, timeout=30)


class Namespaces:
    """Station (S), node (N) and subscriber (C) namespaces with veth pairs S-N and N-C."""

    def __init__(self, tag: str) -> None:
        self.s, self.n, self.c = (f"ssib{tag}{x}" for x in "snc")
        self.made: list[str] = []

    def create(self) -> None:
        if shutil.which("ip") is None:
            pytest.skip("the `ip` tool (iproute2) is not installed")
        for ns in (self.s, self.n, self.c):
            out = _ip("netns", "add", ns)
            if out.returncode != 0:
                self.remove()
                pytest.skip(f"`ip netns add` not permitted here: {out.stderr.strip()}")
            self.made.append(ns)
        tag = self.s[4:-1]
        links = [(f"sb{tag}s", self.s, "10.201.0.2/30", f"sb{tag}n", self.n, "10.201.0.1/30"),
                 (f"sb{tag}m", self.n, "10.201.0.5/30", f"sb{tag}c", self.c, "10.201.0.6/30")]
        steps = []
        for a, ns_a, ip_a, b, ns_b, ip_b in links:
            steps += [("link", "add", a, "type", "veth", "peer", "name", b),
                      ("link", "set", a, "netns", ns_a), ("link", "set", b, "netns", ns_b),
                      ("-n", ns_a, "addr", "add", ip_a, "dev", a),
                      ("-n", ns_b, "addr", "add", ip_b, "dev", b),
                      ("-n", ns_a, "link", "set", a, "up"), ("-n", ns_b, "link", "set", b, "up")]
        for ns in (self.s, self.n, self.c):
            steps.append(("-n", ns, "link", "set", "lo", "up"))
        # multicast (the CAN group, DDS discovery) leaves on the veth toward the peer
        steps += [("-n", self.s, "route", "add", "224.0.0.0/4", "dev", f"sb{tag}s"),
                  ("-n", self.n, "route", "add", "224.0.0.0/4", "dev", f"sb{tag}m"),
                  ("-n", self.c, "route", "add", "224.0.0.0/4", "dev", f"sb{tag}c")]
        for step in steps:
            out = _ip(*step)
            if out.returncode != 0:
                self.remove()
                pytest.fail(f"ip {' '.join(step)}: {out.stderr.strip()}")

    def remove(self) -> None:
        for ns in self.made:
            _ip("netns", "del", ns)  # takes its veth ends (and so the pairs) with it
        self.made.clear()


@pytest.fixture
def namespaces():
    spaces = Namespaces(str(os.getpid() % 100000))
    spaces.create()
    yield spaces
    spaces.remove()


def _env(domain_id: int) -> dict[str, str]:
    env = dds_env(domain_id)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "SUBNET"  # the namespaces' veth subnets only
    env["FASTDDS_BUILTIN_TRANSPORTS"] = "UDPv4"  # no shared memory: a network in between
    return env


def test_station_and_node_on_two_hosts_subscriber_on_a_third(namespaces, domain_id, tmp_path):
    group = f"239.74.201.1:{61000 + domain_id}"
    params = {"joints": ["joint1"], "publish_rate": RATE, "bus.interface": "udp_multicast",
              "storage_path": str(tmp_path / "bank" / "retentive.json")}
    station_file = tmp_path / "station.yaml"
    station_file.write_text(yaml.safe_dump({"/**": {"ros__parameters": {
        **params, "bus.channel": f"{group}@10.201.0.2"}}}))
    node_file = tmp_path / "node.yaml"
    node_file.write_text(yaml.safe_dump({"/**": {"ros__parameters": {
        **params, "simulation.enabled": False, "bus.channel": f"{group}@10.201.0.1"}}}))
    env = _env(domain_id)
    procs: list[subprocess.Popen] = []
    logs = {name: tmp_path / f"{name}.log" for name in ("station", "node")}
    try:
        with open(logs["station"], "wb") as log:
            station = subprocess.Popen(
                ["ip", "netns", "exec", namespaces.s, str(installed_executable("station")), "--params-file",
                 str(station_file)], stdout=subprocess.PIPE, stderr=log, env=env)
        procs.append(station)
        ready = station.stdout.readline().decode()
        assert ready.startswith("station ready"), logs["station"].read_text()
        with open(logs["node"], "wb") as log:
            node = subprocess.Popen(
                ["ip", "netns", "exec", namespaces.n, str(installed_executable("ssi_bridge_node")), "--ros-args",
                 "--params-file", str(node_file)], stdout=log, stderr=subprocess.STDOUT,
                env=env)
        procs.append(node)
        sub = subprocess.run(
            ["ip", "netns", "exec", namespaces.c, sys.executable, str(SUBSCRIBER), "3.0",
             str(REG_LOWER_LIMIT), "4321"], capture_output=True, text=True, env=env,
            timeout=150)
        assert node.poll() is None, logs["node"].read_text()[-3000:]
        assert sub.returncode == 0 and sub.stdout.strip(), (sub.stderr[-3000:],
                                                           logs["node"].read_text()[-3000:])
        result = json.loads(sub.stdout.strip().splitlines()[-1])
    finally:
        for proc in reversed(procs):
            stop_station(proc)
    stamps = result["stamps"]
    assert len(stamps) > 10, ("no joint_states crossed the network", logs["node"].read_text())
    spacing = statistics.median(b - a for a, b in zip(stamps, stamps[1:])) / 1e9
    span = (stamps[-1] - stamps[0]) / 1e9
    assert spacing == pytest.approx(1.0 / RATE, rel=0.1), "cycles at the configured rate"
    assert len(stamps) >= 0.8 * span * RATE, "messages lost on the way to the third host"
    assert result["write"] and result["write"][0], result
    assert result["read"] and result["read"][0] and result["read"][1] == 4321, result
    assert station.returncode == 0 and node.returncode == 0
