"""The live view's services and parameters, used as Foxglove's panels use them.

The client here speaks the Foxglove WebSocket protocol (subprotocol ``foxglove.sdk.v1``)
itself: ``advertiseServices``, the binary Service Call Request (opcode 0x02: service id, call
id, encoding, payload) and Service Call Response (0x03), ``getParameters`` /
``setParameters`` / ``subscribeParameterUpdates`` answered by ``parameterValues``, ``status``.
It encodes requests and decodes responses only with the ``ros2msg`` schemas the server
advertised (mcap_ros2's dynamic codec), as Foxglove does; the ROS side of each comparison is
the same service called over DDS.
"""

from __future__ import annotations

import asyncio
import json
import statistics
from typing import Any

from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import GetParameters, ListParameters, SetParameters
from sensor_msgs.msg import JointState
from ssi_bridge_msgs.msg import Event
from ssi_bridge_msgs.srv import ReadRegister, SetPreset

from support.liveview import LiveViewClient, free_port, session

#: a joint that stands still: two presets to one position give the same answer
STILL = {"joint1.motion.kind": "still"}
#: INVALID_BITS_LSB 15 + INVALID_BITS_MSB 7 = 22 bits with a 20-bit frame (000 Table 19)
BAD_PARA1 = 0x14017F00


def test_services_answer_as_the_ros_services_do(running, probe):
    port = free_port()
    node = running({"foxglove.port": port, **STILL})
    events = probe.subscribe(Event, node.topic("~/events"), qos=100)
    srv = node.topic("~/read_register").rsplit("/", 1)[0]

    async def body(client: LiveViewClient) -> dict:
        out = {"services": dict(client.services), "capabilities": client.info["capabilities"],
               "encodings": client.info.get("supportedEncodings")}
        out["read"] = await client.call(f"{srv}/read_register", {"joint": "", "address": 20})
        out["bad"] = await client.call(f"{srv}/read_register", {"joint": "", "address": 64})
        out["nobody"] = await client.call(f"{srv}/read_register",
                                          {"joint": "nobody", "address": 20})
        out["preset"] = await client.call(f"{srv}/set_preset", {"joint": "", "position": 1.0})
        # a payload that is no ReadRegister request: a failure with the reason, nothing stops
        out["garbage"] = await client.call_raw(f"{srv}/read_register", b"\x00\x01\xff")
        out["after"] = await client.call(f"{srv}/read_register", {"joint": "", "address": 20})
        return out

    fox = session(port, body)
    assert {"services", "parameters"} <= set(fox["capabilities"])
    assert fox["encodings"] == ["cdr"], "Foxglove calls services only in an offered encoding"
    names = {f"{srv}/{n}" for n in ("read_register", "write_register", "set_preset",
                                    "reset_registers", "set_control", "inject_fault",
                                    "start_recording", "stop_recording")}
    assert names <= set(fox["services"]), sorted(fox["services"])
    read = fox["services"][f"{srv}/read_register"]
    assert read["type"] == "ssi_bridge_msgs/srv/ReadRegister"
    assert read["request"]["schemaName"] == "ssi_bridge_msgs/srv/ReadRegister_Request"
    assert {read["request"]["encoding"], read["request"]["schemaEncoding"]} == {"cdr", "ros2msg"}
    assert "uint32 value" in read["response"]["schema"].replace("  ", " ")

    ros_read = probe.call(ReadRegister, node.topic("~/read_register"),
                          ReadRegister.Request(address=20))
    ros_bad = probe.call(ReadRegister, node.topic("~/read_register"),
                         ReadRegister.Request(address=64))
    ros_nobody = probe.call(ReadRegister, node.topic("~/read_register"),
                            ReadRegister.Request(joint="nobody", address=20))
    ros_preset = probe.call(SetPreset, node.topic("~/set_preset"),
                            SetPreset.Request(position=1.0))
    for got, want in ((fox["read"], ros_read), (fox["bad"], ros_bad),
                      (fox["nobody"], ros_nobody)):
        assert (got.success, got.message, got.value) == (want.success, want.message, want.value)
    assert fox["read"].success and not fox["bad"].success and not fox["nobody"].success
    assert "nobody" in fox["nobody"].message
    kind, text = fox["garbage"]
    assert kind == "failure" and "does not decode as ssi_bridge_msgs/srv/ReadRegister_Request" \
        in text.decode(), (kind, text)
    assert fox["after"].success and fox["after"].value == fox["read"].value
    p = fox["preset"]
    assert p.success, p.message
    assert (p.success, p.message, p.offset) == (ros_preset.success, ros_preset.message,
                                                ros_preset.offset)
    assert abs(p.position - 1.0) < 1e-3 and abs(ros_preset.position - 1.0) < 1e-3
    # the same ~/events records: two of each call, one per path
    probe.wait_for(lambda: sum(e.kind == "set_preset" for _, e in events) >= 2, 10.0,
                   "the set_preset events", node)
    presets = [e for _, e in events if e.kind == "set_preset"]
    assert [(e.request, e.success, e.message) for e in presets[:2]] == \
           [("position=1.0", True, p.message)] * 2
    refused = [e for _, e in events if e.kind == "read_register" and not e.success]
    assert len(refused) >= 4 and refused[0].message == fox["bad"].message


def _get(probe, node, name: str) -> Any:
    return probe.call(GetParameters, node.topic("~/get_parameters"),
                      GetParameters.Request(names=[name])).values[0]


def _median_period(msgs: list[tuple[float, Any]]) -> float:
    stamps = [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for _, m in msgs]
    return statistics.median(b - a for a, b in zip(stamps, stamps[1:]))


def test_parameters_are_read_set_and_watched_through_the_node_checks(running, probe):
    port = free_port()
    node = running({"foxglove.port": port, "publish_rate": 100.0})
    fqn = node.topic("~/x").rsplit("/", 1)[0]
    rate_name, para1_name = f"{fqn}.publish_rate", f"{fqn}.joint1.para1"
    events = probe.subscribe(Event, node.topic("~/events"), qos=100)
    # what `ros2 param set` answers for the same invalid REG_PARA1
    ros_refusal = probe.call(SetParameters, node.topic("~/set_parameters"), SetParameters.Request(
        parameters=[Parameter(name="joint1.para1", value=ParameterValue(
            type=ParameterType.PARAMETER_INTEGER, integer_value=BAD_PARA1))])).results[0]
    assert not ros_refusal.successful and "INVALID_BITS" in ros_refusal.reason

    async def body(client: LiveViewClient) -> dict:
        out: dict[str, Any] = {}
        everything = await client.parameters("getParameters", parameterNames=[])
        out["all"] = {p["name"]: p for p in everything}
        await client.ws.send(json.dumps({"op": "subscribeParameterUpdates",
                                         "parameterNames": [rate_name]}))
        out["set"] = await client.parameters(  # JSON's 20: a whole number for a float
            "setParameters", parameters=[{"name": rate_name, "value": 20}])
        out["bad"] = await client.parameters(
            "setParameters", parameters=[{"name": para1_name, "value": BAD_PARA1}])
        out["ro"] = await client.parameters(
            "setParameters", parameters=[{"name": f"{fqn}.bus.node_id", "value": 5}])
        await client.pump(lambda: sum(m["op"] == "status" for m in client.texts) >= 2)
        out["status"] = [m["message"] for m in client.texts if m["op"] == "status"]
        # a change made over ROS reaches the subscribed client
        mark = len(client.texts)
        await asyncio.to_thread(probe.call, SetParameters, node.topic("~/set_parameters"),
                                SetParameters.Request(parameters=[Parameter(
                                    name="publish_rate", value=ParameterValue(
                                        type=ParameterType.PARAMETER_DOUBLE,
                                        double_value=25.0))]))
        await client.pump(lambda: any(m["op"] == "parameterValues" and "id" not in m
                                      for m in client.texts[mark:]))
        out["update"] = next(m for m in client.texts[mark:]
                             if m["op"] == "parameterValues" and "id" not in m)["parameters"]
        return out

    fox = session(port, body)
    assert fox["all"][rate_name]["value"] == 100.0 and fox["all"][rate_name]["type"] == "float64"
    assert fox["all"][f"{fqn}.joints"]["value"] == ["joint1"]
    assert fox["all"][para1_name]["value"] == _get(probe, node, "joint1.para1").integer_value
    declared = probe.call(ListParameters, node.topic("~/list_parameters"),
                          ListParameters.Request()).result.names
    assert set(fox["all"]) == {f"{fqn}.{n}" for n in declared}, "every declared parameter"
    assert fox["set"] == [{"name": rate_name, "type": "float64", "value": 20.0}]
    assert fox["bad"][0]["value"] != BAD_PARA1, "a refused value is not taken"
    assert f"{para1_name}: refused: {ros_refusal.reason}" in fox["status"], fox["status"]
    assert any(s.startswith(f"{fqn}.bus.node_id: refused:") and "read-only" in s
               for s in fox["status"]), fox["status"]
    assert fox["update"] == [{"name": rate_name, "type": "float64", "value": 25.0}]
    assert _get(probe, node, "publish_rate").double_value == 25.0
    # the rate the live view set (20 Hz) was applied by the node's own callback; now 25 Hz
    seen = probe.subscribe(JointState, node.topic("joint_states"), qos=500)
    probe.wait_for(lambda: len(seen) >= 30, 20.0, "joint_states at the new rate", node)
    assert 0.030 <= _median_period(seen[-25:]) <= 0.050, _median_period(seen[-25:])
    changes = [e for _, e in events if e.kind == "set_parameters"]
    assert any(e.success and e.request == "publish_rate=20.0" for e in changes), changes
    assert sum(not e.success and "INVALID_BITS" in e.message for e in changes) >= 2


def test_services_and_parameters_can_be_left_out(running):
    port = free_port()
    running({"foxglove.port": port, "foxglove.services": False,
             "foxglove.parameters": False})

    async def body(client: LiveViewClient) -> dict:
        # the channels are advertised after serverInfo; services would come with them
        await client.pump(lambda: any(m["op"] == "advertise" for m in client.texts))
        await client.drain(2.0)
        return {"capabilities": client.info["capabilities"],
                "ops": {m["op"] for m in client.texts}}

    fox = session(port, body)
    assert not {"services", "parameters"} & set(fox["capabilities"]), fox["capabilities"]
    assert "advertiseServices" not in fox["ops"] and "advertise" in fox["ops"]
