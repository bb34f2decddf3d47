"""`ros2 param dump` of the node, and its dump loaded back into a node.

ros2cli's ``ros2 param dump`` nests parameter names on ``.`` (ros2param's ``insert_dict``:
``bus.channel`` becomes ``bus: {channel: ...}``) and writes ``{<node>: {ros__parameters:
...}}``. A name that is both a value and the prefix of another (the node once declared
``simulation`` beside ``simulation.transport``) breaks it: the dump raised ``TypeError: 'bool'
object does not support item assignment``, and no nested params file can hold both. The
renamed parameter's old name is refused at start-up in one line that names the new one
(test_node_start_refusals.py, with the joint names that would make a value a prefix).
"""

from __future__ import annotations

import subprocess
from pathlib import Path
from typing import Any

import pytest
import yaml
from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import GetParameters, ListParameters

from ssi_bridge.ros.param_table import JOINT_PARAMETERS, NODE_PARAMETERS, RENAMED

from .conftest import NodeProcess, dds_env, installed_executable

#: what rclpy declares on every node beside the node's own table
RCLPY_DECLARED = ("use_sim_time", "start_type_description_service")


def nest(flat: dict[str, Any]) -> dict[str, Any]:
    """``flat`` nested the way ``ros2 param dump`` nests it: each name split on every ``.``,
    one mapping level per part. A name that is a value and also a prefix fails (in either
    order: ros2param raises for one and silently drops the other)."""
    out: dict[str, Any] = {}
    for name, value in flat.items():
        *parents, leaf = name.split(".")
        level = out
        for k, part in enumerate(parents):
            level = level.setdefault(part, {})
            if not isinstance(level, dict):
                pytest.fail(f"'{'.'.join(parents[:k + 1])}' is a value and the prefix of "
                            f"'{name}': ros2 param dump cannot nest both")
        if isinstance(level.get(leaf), dict):
            pytest.fail(f"'{name}' is a value and the prefix of other parameters: ros2 param "
                        "dump cannot nest both")
        level[leaf] = value
    return out


def _value(v: Any) -> Any:
    """A ParameterValue as the Python value ``ros2 param dump`` writes."""
    return {ParameterType.PARAMETER_BOOL: lambda: v.bool_value,
            ParameterType.PARAMETER_INTEGER: lambda: v.integer_value,
            ParameterType.PARAMETER_DOUBLE: lambda: v.double_value,
            ParameterType.PARAMETER_STRING: lambda: v.string_value,
            ParameterType.PARAMETER_INTEGER_ARRAY: lambda: list(v.integer_array_value),
            ParameterType.PARAMETER_DOUBLE_ARRAY: lambda: list(v.double_array_value),
            ParameterType.PARAMETER_STRING_ARRAY: lambda: list(v.string_array_value),
            ParameterType.PARAMETER_BOOL_ARRAY: lambda: list(v.bool_array_value)}[v.type]()


def _all_parameters(probe, node: NodeProcess) -> dict[str, Any]:
    """Every parameter of ``node`` with its value, fetched as ``ros2 param dump`` does."""
    names = probe.call(ListParameters, node.topic("~/list_parameters"),
                       ListParameters.Request()).result.names
    values = probe.call(GetParameters, node.topic("~/get_parameters"),
                        GetParameters.Request(names=list(names))).values
    return {n: _value(v) for n, v in zip(names, values)}


def test_the_declared_table_nests_without_a_clash() -> None:
    names = [*NODE_PARAMETERS, *RCLPY_DECLARED,
             *(f"{joint}.{key}" for joint in ("shoulder", "carriage") for key in JOINT_PARAMETERS)]
    nested = nest({name: 0 for name in names})
    assert nested["simulation"]["enabled"] == 0 and nested["shoulder"]["motion"]["kind"] == 0
    assert not set(RENAMED) & set(NODE_PARAMETERS), "an old name is declared no more"


def test_every_parameter_dumps_nested_and_the_dump_starts_a_node(
        start_node, probe, tmp_path: Path, domain_id: int) -> None:
    given = {"joints": ["shoulder", "carriage"], "publish_rate": 50.0,
             "simulation.transport": "virtual", "carriage.family": "TTK70",
             "record.snapshot.after": 2.5, "diagnostics_period": 0.5}
    first = start_node(given)
    first.wait_for_log("bridging")
    dumped = _all_parameters(probe, first)
    assert {"simulation.enabled", "simulation.transport", "carriage.motion.kind"} <= set(dumped)
    assert all(dumped[k] == v for k, v in given.items()), dumped
    dump = tmp_path / "ssi_bridge.yaml"
    dump.write_text(yaml.safe_dump({"/ssi_bridge": {"ros__parameters": nest(dumped)}}))
    assert first.stop() == 0, first.log()[-2000:]

    log_path = tmp_path / "from_dump.log"
    with open(log_path, "wb") as log:
        proc = subprocess.Popen(
            [str(installed_executable("ssi_bridge_node")), "--ros-args", "--params-file",
             str(dump)], stdout=log, stderr=subprocess.STDOUT, env=dds_env(domain_id),
            cwd=tmp_path, start_new_session=True)
    second = NodeProcess(proc, domain_id, "", log_path)
    try:
        second.wait_for_log("bridging")
        assert _all_parameters(probe, second) == dumped
        assert "not a parameter of this node" not in second.log(), second.log()[-2000:]
    finally:
        assert second.stop() == 0, second.log()[-2000:]
