"""config/diagnostic_analyzers.yaml: every status the node publishes lands in exactly one analyzer.

diagnostic_aggregator is not installed here, so GenericAnalyzer's matching is re-implemented
from its documentation (generic_analyzer.hpp / README of ros/diagnostics, Jazzy) and its
``match()``: a status name matches an analyzer when any of

* ``regex``: a full match of the name (std::regex_match, ECMAScript grammar),
* ``expected`` / ``name``: the exact name,
* ``startswith`` (and ``find_and_remove_prefix``, which is startswith + remove_prefix): a prefix,
* ``contains``: a substring

holds. The aggregator offers each status to every analyzer, so an overlap would show a status
twice and a miss would leave it under "Other". Output names are ``path + "/" +`` the status
name with every "/" turned into a space (``getOutputName`` of status_item.hpp), then drop
``remove_prefix`` the way ``removeLeadingNameChaff`` does (the prefix, then one ':' and any
spaces after it). Status names are ``<node FQN>: <joint>`` (ARCHITECTURE.md).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest
import yaml

REPO = Path(__file__).resolve().parents[2]
CONFIG = REPO / "config" / "diagnostic_analyzers.yaml"
STATION = REPO / "config" / "ssi_bridge.yaml"
NODE_SRC = REPO / "ssi_bridge" / "ros" / "node_status.py"  # where the node names its statuses

BUS_STATUS = "/ssi_bridge: bus"
MATCHERS = ("regex", "expected", "name", "startswith", "find_and_remove_prefix", "contains")
GENERIC = "diagnostic_aggregator/GenericAnalyzer"
GROUP = "diagnostic_aggregator/AnalyzerGroup"


def _strings(value: Any) -> list[str]:
    """A matcher parameter: the docs allow one string or a list of strings."""
    if value is None:
        return []
    return [value] if isinstance(value, str) else [str(v) for v in value]


def generic_match(params: dict[str, Any], name: str) -> bool:
    """GenericAnalyzer::match: regex (full match), expected, name, startswith, contains."""
    if any(re.fullmatch(rx, name) for rx in _strings(params.get("regex"))):
        return True
    if name in _strings(params.get("expected")) or name in _strings(params.get("name")):
        return True
    prefixes = _strings(params.get("startswith")) + _strings(params.get("find_and_remove_prefix"))
    if any(name.startswith(p) for p in prefixes):
        return True
    return any(c in name for c in _strings(params.get("contains")))


def output_name(path: str, status: str) -> str:
    """StatusItem::toStatusMsg: the analyzer path, "/", the name with "/" as spaces."""
    return f"{path}/{status.replace('/', ' ')}"


def remove_leading_chaff(output_name: str, chaff: str) -> str:
    """diagnostic_aggregator::removeLeadingNameChaff on the last path element."""
    if not chaff:
        return output_name
    last = output_name.rfind("/")
    head, tail = output_name[:last + 1], output_name[last + 1:]
    if tail.startswith(chaff):
        tail = tail[len(chaff):]
    if tail.startswith(":"):
        tail = tail[1:]
    return head + tail.lstrip(" ")


def _analyzers(params: dict[str, Any], path: str) -> dict[str, tuple[str, dict[str, Any]]]:
    """name -> (full output path, parameters) of every GenericAnalyzer, groups flattened."""
    found: dict[str, tuple[str, dict[str, Any]]] = {}
    for key, value in params.items():
        if not isinstance(value, dict) or "type" not in value:
            continue
        sub_path = f"{path}/{value.get('path', '')}"
        if value["type"] == GROUP:
            found.update({f"{key}.{k}": v for k, v in
                          _analyzers(value.get("analyzers", {}), sub_path).items()})
        else:
            found[key] = (sub_path, value)
    return found


@pytest.fixture(scope="module")
def config() -> dict[str, Any]:
    return yaml.safe_load(CONFIG.read_text())


@pytest.fixture(scope="module")
def analyzers(config: dict[str, Any]) -> dict[str, tuple[str, dict[str, Any]]]:
    params = config["analyzers"]["ros__parameters"]
    return _analyzers(params, "/" + params.get("path", "").strip("/"))


def joint_status_name(joint: str, node_fqn: str = "/ssi_bridge") -> str:
    """The name the node gives a joint's DiagnosticStatus (from the node's own code)."""
    from ssi_bridge.ros.diagnostics import (
        ChannelCounters, ChannelHealth, channel_status, status_name,
    )

    return channel_status(status_name(node_fqn, joint), "hw", ChannelCounters(),
                          ChannelHealth(), 0.0).name


def _station_joints() -> list[str]:
    doc = yaml.safe_load(STATION.read_text())
    return list(doc["/**"]["ros__parameters"]["joints"])


JOINTS = ["joint1", "j1", "j8", "lift", "bus_axis", "busbar", "omnibus"]


def test_layout_follows_the_aggregator_format(config: dict[str, Any],
                                              analyzers: dict[str, Any]) -> None:
    params = config["analyzers"]["ros__parameters"]
    assert params["path"] == "SSI Bridge"
    assert set(analyzers) == {"joints", "bus", "stations"}
    for key, (_path, p) in analyzers.items():
        assert p["type"] == GENERIC, key
        assert isinstance(p.get("path"), str) and p["path"], key
        used = [m for m in MATCHERS if m in p]
        assert used, f"{key}: GenericAnalyzer without any matcher is refused at start-up"
        for m in used + ["remove_prefix"]:
            if m in p:
                # Jazzy reads these with as_string_array(): a bare string would be refused
                assert isinstance(p[m], list) and all(isinstance(v, str) for v in p[m]), (key, m)
        for rx in p.get("regex", []):
            re.compile(rx)


def test_bus_status_name_is_the_one_the_node_publishes() -> None:
    from ssi_bridge.ros.diagnostics import status_name

    assert 'status_name(fqn, "bus")' in NODE_SRC.read_text(), \
        "node renamed its bus status: update the config"
    assert status_name("/ssi_bridge", "bus") == BUS_STATUS
    assert joint_status_name("joint1") == "/ssi_bridge: joint1"


@pytest.mark.parametrize("joint", JOINTS + _station_joints())
def test_each_joint_status_matches_only_the_joints_analyzer(
        analyzers: dict[str, Any], joint: str) -> None:
    name = joint_status_name(joint)
    hits = [key for key, (_path, p) in analyzers.items() if generic_match(p, name)]
    assert hits == ["joints"], f"{name!r} matched by {hits}"
    path, p = analyzers["joints"]
    out = output_name(path, name)
    for chaff in p.get("remove_prefix", []):
        out = remove_leading_chaff(out, chaff)
    assert out == f"/SSI Bridge/Joints/{joint}"


@pytest.mark.parametrize("ns", ["/station_a", "/cell/station_b"])
def test_namespaced_bridges_land_in_the_same_analyzers_under_distinct_names(
        analyzers: dict[str, Any], ns: str) -> None:
    from ssi_bridge.ros.diagnostics import status_name

    outs = set()
    for fqn in (f"{ns}/ssi_bridge", "/ssi_bridge"):
        name = joint_status_name("shoulder", fqn)
        hits = [key for key, (_path, p) in analyzers.items() if generic_match(p, name)]
        assert hits == ["joints"], f"{name!r} matched by {hits}"
        bus = status_name(fqn, "bus")
        assert [k for k, (_p, p) in analyzers.items() if generic_match(p, bus)] == ["bus"]
        path, p = analyzers["joints"]
        out = output_name(path, name)
        for chaff in p.get("remove_prefix", []):
            out = remove_leading_chaff(out, chaff)
        outs.add(out)
    assert len(outs) == 2, f"two stations must not merge: {outs}"
    assert f"/SSI Bridge/Joints/{ns.replace('/', ' ').strip()} ssi_bridge: shoulder" in outs


def test_bus_status_matches_only_the_bus_analyzer(analyzers: dict[str, Any]) -> None:
    hits = [key for key, (_path, p) in analyzers.items() if generic_match(p, BUS_STATUS)]
    assert hits == ["bus"], f"{BUS_STATUS!r} matched by {hits}"
    path, p = analyzers["bus"]
    out = output_name(path, BUS_STATUS)
    for chaff in p.get("remove_prefix", []):
        out = remove_leading_chaff(out, chaff)
    assert out == "/SSI Bridge/Bus/bus"


@pytest.mark.parametrize("fqn", ["/ssi_bridge", "/cell/ssi_bridge"])
@pytest.mark.parametrize("station", [1, 3, 127])
def test_station_status_matches_only_the_stations_analyzer(analyzers: dict[str, Any],
                                                           fqn: str, station: int) -> None:
    """Several stations on one bus: "<node FQN>: station <node ID>" (the node's own name)."""
    from ssi_bridge.ros.diagnostics import station_status, status_name

    name = station_status(status_name(fqn, f"station {station}"), "hw", alive=True,
                          nmt_state="OPERATIONAL", emcy=[], counters={}).name
    assert 'status_name(fqn, f"station {sid}")' in NODE_SRC.read_text(), \
        "node renamed its station status: update the config"
    hits = [key for key, (_path, p) in analyzers.items() if generic_match(p, name)]
    assert hits == ["stations"], f"{name!r} matched by {hits}"
    path, p = analyzers["stations"]
    out = output_name(path, name)
    for chaff in p.get("remove_prefix", []):
        out = remove_leading_chaff(out, chaff)
    prefix = fqn.rsplit("/", 1)[0].replace("/", " ").strip()
    assert out == f"/SSI Bridge/Stations/{prefix + ' ssi_bridge: ' if prefix else ''}station {station}"


@pytest.mark.parametrize("name", ["other_node: bus", "/other_node: bus", "/ssi_bridge",
                                  "/ssi_bridge: ", "my /ssi_bridge: joint1",
                                  "/ssi_bridge:joint1", "/my_ssi_bridge: joint1",
                                  "ssi_bridge: joint1"])
def test_foreign_statuses_are_left_to_other_analyzers(analyzers: dict[str, Any],
                                                      name: str) -> None:
    hits = [key for key, (_path, p) in analyzers.items() if generic_match(p, name)]
    assert hits == [], f"{name!r} matched by {hits}"


def test_matching_rules_as_documented() -> None:
    """The re-implementation itself, on the documentation's own kinds of example."""
    assert generic_match({"startswith": ["Battery", "IBPS"]}, "IBPS 3")
    assert generic_match({"contains": "/motor"}, "/arms/left/motor")
    assert generic_match({"expected": "Power board 1000"}, "Power board 1000")
    assert not generic_match({"name": ["Power board"]}, "Power board 1000")
    assert generic_match({"find_and_remove_prefix": ["hokuyo_node"]}, "hokuyo_node: Connection")
    assert generic_match({"regex": ["Joint.*"]}, "Joint 3")
    assert not generic_match({"regex": ["Joint"]}, "Joint 3"), "regex is a full match"
    assert (remove_leading_chaff("/Hokuyo/Tilt HK/tilt_node: Connection", "tilt_node")
            == "/Hokuyo/Tilt HK/Connection")
