"""Parameters (declared with descriptors and ranges, runtime REG_PARA1 changes refused with the
module's ERR_PARA reason, 000 Table 19) and the process life cycle (clean exit codes)."""

from __future__ import annotations


import signal
from pathlib import Path

import pytest
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import DescribeParameters, SetParameters
from ssi_bridge_msgs.srv import ReadRegister


def _set(probe, node, name, value):
    v = ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=value)
    req = SetParameters.Request(parameters=[Parameter(name=name, value=v)])
    res = probe.call(SetParameters, node.topic("~/set_parameters"), req)
    return res.results[0]


def _core(by_name, node, probe) -> None:
    assert all(d.description for d in by_name.values()), "every parameter says what it means"
    rate = by_name["publish_rate"].floating_point_range[0]
    assert (rate.from_value, rate.to_value) == (1.0, 2000.0)
    node_id = by_name["bus.node_id"].integer_range[0]
    assert (node_id.from_value, node_id.to_value) == (1, 127) and by_name["bus.node_id"].read_only
    assert "REG_PARA1" in by_name["joint1.para1"].description


def _split(by_name, node, probe) -> None:
    # (from test_node_split.py: the descriptors are the node's whatever its configuration)
    size, duration = by_name["record.max_size"], by_name["record.max_duration"]
    assert "bytes" in size.description and "seconds" in duration.description
    assert size.integer_range[0].from_value == 0 and duration.integer_range[0].from_value == 0
    assert size.read_only and duration.read_only


def _foxglove(by_name, node, probe) -> None:
    # (from test_node_liveview.py: off by default, described with a port range)
    from diagnostic_msgs.msg import DiagnosticArray
    from rcl_interfaces.srv import GetParameters

    port = by_name["foxglove.port"].integer_range[0]
    assert (port.from_value, port.to_value) == (0, 65535)
    assert all(d.read_only and d.description for d in by_name.values())
    values = probe.call(GetParameters, node.topic("~/get_parameters"),
                        GetParameters.Request(names=["foxglove.port", "foxglove.address"])).values
    assert (values[0].integer_value, values[1].string_value) == (0, "127.0.0.1")
    diags = probe.subscribe(DiagnosticArray, "/diagnostics")
    probe.wait_for(lambda: any(s.name == "/ssi_bridge: bus" for _, d in diags for s in d.status),
                   10.0, "bus diagnostics", node)
    bus = next(s for _, d in diags for s in d.status if s.name == "/ssi_bridge: bus")
    assert dict((kv.key, kv.value) for kv in bus.values)["liveview_port"] == "0"
    assert "live view" not in node.log()


DESCRIBED = {
    "core": (["publish_rate", "bus.node_id", "joint1.para1", "joint1.slot", "record.root"], _core),
    "split": (["record.max_size", "record.max_duration"], _split),
    "foxglove": (["foxglove.port", "foxglove.address"], _foxglove),
}


@pytest.mark.parametrize("group", DESCRIBED)
def test_parameters_are_described_with_ranges(shared_node, shared_probe, group):
    node = shared_node()  # descriptions only: one default node serves every group
    names, check = DESCRIBED[group]
    res = shared_probe.call(DescribeParameters, node.topic("~/describe_parameters"),
                            DescribeParameters.Request(names=names))
    by_name = {d.name: d for d in res.descriptors}
    assert set(by_name) == set(names)
    check(by_name, node, shared_probe)


def test_runtime_para1_change_is_validated_by_the_module_rules(running, probe):
    node = running()
    # INVALID_BITS_LSB 15 + INVALID_BITS_MSB 7 = 22 is fine, but with a 20-bit frame it is not
    bad = _set(probe, node, "joint1.para1", 0x14017F00)
    assert not bad.successful
    assert "INVALID_BITS" in bad.reason and "SSI_FRAME_LEN" in bad.reason, bad.reason
    reserved_rate = _set(probe, node, "joint1.para1", 0x19090000)  # bit-rate code 9: reserved
    assert not reserved_rate.successful and "SSI_BIT_RATE" in reserved_rate.reason
    good = _set(probe, node, "joint1.para1", 0x19030000)  # 125 kbit/s, not the default
    assert good.successful, good.reason
    back = probe.call(ReadRegister, node.topic("~/read_register"), ReadRegister.Request(address=20))
    assert back.success and back.value == 0x19030000


@pytest.mark.parametrize("name, value, words", [
    # out of the descriptor's range (1..2000 Hz)
    ("publish_rate", ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=5000.0),
     ""),
    # read-only at run time
    ("bus.node_id", ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=5),
     "read-only"),
], ids=["out_of_range", "read_only"])
def test_a_refused_parameter_set_changes_nothing(shared_node, shared_probe, name, value, words):
    node = shared_node()  # refused: the node is unchanged
    res = shared_probe.call(SetParameters, node.topic("~/set_parameters"),
                            SetParameters.Request(parameters=[Parameter(name=name, value=value)]))
    assert not res.results[0].successful
    assert words in res.results[0].reason.lower(), res.results[0].reason


def test_sigterm_closes_the_recording_and_exits_zero(running, probe, tmp_path: Path):
    from mcap.reader import make_reader

    root = tmp_path / "rec"
    node = running({"record.enabled": True, "record.root": str(root), "record.path": "s"})
    probe.wait_for(lambda: (root / "s").exists(), 5.0, "the bag directory", node)
    assert node.stop(signal.SIGTERM) == 0, node.log()[-3000:]
    assert (root / "s" / "metadata.yaml").exists(), "metadata.yaml written on shutdown"
    with open(root / "s" / "s_0.mcap", "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics.message_count > 0


def test_publish_rate_change_takes_effect_at_once(running, probe):
    import time

    from sensor_msgs.msg import JointState

    node = running({"publish_rate": 100.0})
    msgs = probe.subscribe(JointState, node.topic("joint_states"))
    v = ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=20.0)
    res = probe.call(SetParameters, node.topic("~/set_parameters"),
                     SetParameters.Request(parameters=[Parameter(name="publish_rate", value=v)]))
    assert res.results[0].successful, res.results[0].reason
    time.sleep(0.3)
    start, t0 = len(msgs), time.monotonic()
    time.sleep(2.0)
    rate = (len(msgs) - start) / (time.monotonic() - t0)
    assert abs(rate - 20.0) <= 2.0, f"{rate:.1f} Hz after setting publish_rate to 20"


def test_cpu_affinity_pins_every_thread_of_the_node(running):
    import os

    cpu = max(os.sched_getaffinity(0))
    node = running({"cpu_affinity": [cpu]})
    pid = node.proc.pid
    allowed = set()
    for tid in os.listdir(f"/proc/{pid}/task"):
        allowed.add(frozenset(os.sched_getaffinity(int(tid))))
    assert allowed == {frozenset({cpu})}, f"threads allowed on {allowed}"


def test_sigterm_while_the_node_is_still_starting_exits_zero(start_node, tmp_path: Path):
    # the signal lands while __init__ finishes (just after the start-up recording opened),
    # before the executor exists: rclpy has shut the context down, the node must still exit 0
    import time

    for attempt in range(3):
        node = start_node({"record.enabled": True, "record.root": str(tmp_path / f"r{attempt}")})
        deadline = time.monotonic() + 30
        while "recording to" not in node.log():
            assert node.proc.poll() is None, node.log()
            assert time.monotonic() < deadline, node.log()
            time.sleep(0.001)
        node.proc.send_signal(signal.SIGTERM)
        assert node.proc.wait(20) == 0, node.log()[-3000:]
        assert "Traceback" not in node.log()


# -- cycle_priority (docs/node.md "The cycle", Scheduling) --------------------------------------
def _threads(pid: int) -> dict[str, set[tuple[int, int]]]:
    """Kernel thread name -> {(policy, priority)} of the threads of ``pid``."""
    import os

    out: dict[str, set[tuple[int, int]]] = {}
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            tid = int(task.name)
            got = os.sched_getscheduler(tid), os.sched_getparam(tid).sched_priority
            out.setdefault((task / "comm").read_text().strip(), set()).add(got)
        except OSError:
            continue  # that thread ended meanwhile
    return out


def _cycle_thread(pid: int) -> tuple[int, int]:
    """(policy, priority) of the node's cycle thread, checking that the master's receive
    thread (ssi_can_rx) runs the same way: both keep the bus's time."""
    threads = _threads(pid)
    assert "ssi_cycle" in threads and "ssi_can_rx" in threads, sorted(threads)
    assert threads["ssi_can_rx"] == threads["ssi_cycle"], threads
    (got,) = threads["ssi_cycle"]
    return got


def _bus_value(probe, node, key: str) -> str:
    from diagnostic_msgs.msg import DiagnosticArray

    diags = probe.subscribe(DiagnosticArray, "/diagnostics", qos=50)
    probe.wait_for(lambda: any(s.name.endswith(": bus") for _, a in list(diags) for s in a.status),
                   10.0, "the bus status", node)
    bus = [s for _, a in list(diags) for s in a.status if s.name.endswith(": bus")][-1]
    return {kv.key: kv.value for kv in bus.values}[key]


def _without_sys_nice() -> None:
    """preexec: the node may not use SCHED_FIFO (no CAP_SYS_NICE after exec, rtprio limit 0)."""
    import ctypes
    import resource

    pr_capbset_drop, cap_sys_nice = 24, 23
    if ctypes.CDLL(None, use_errno=True).prctl(pr_capbset_drop, cap_sys_nice, 0, 0, 0) != 0:
        raise OSError(ctypes.get_errno(), "PR_CAPBSET_DROP CAP_SYS_NICE")
    resource.setrlimit(resource.RLIMIT_RTPRIO, (0, 0))


def _may_drop_sys_nice() -> bool:
    import os

    return os.geteuid() == 0


def test_the_cycle_runs_at_cycle_priority_or_says_why_not(running, probe):
    """Default cycle_priority 5: the cycle thread and the master's receive thread (and only
    they) run SCHED_FIFO 5 and the bus status says so; without the right to it, normal
    scheduling, one INFO line naming the parameter, and the node still publishes; 0: normal
    and no such line."""
    import os

    from sensor_msgs.msg import JointState

    node = running({"diagnostics_period": 0.5})
    got = _cycle_thread(node.proc.pid)
    if got == (os.SCHED_FIFO, 5):
        assert _bus_value(probe, node, "cycle_scheduling") == "SCHED_FIFO 5"
        assert _bus_value(probe, node, "receive_scheduling") == "SCHED_FIFO 5"
        others = {got for name, policies in _threads(node.proc.pid).items()
                  if name not in ("ssi_cycle", "ssi_can_rx") for got in policies}
        assert others == {(os.SCHED_OTHER, 0)}, "only the bus's two threads are real-time"
    else:
        assert got == (os.SCHED_OTHER, 0)
        assert "SCHED_FIFO 5 not permitted" in node.log()
    assert node.stop() == 0

    if _may_drop_sys_nice():
        node = running({"diagnostics_period": 0.5}, preexec=_without_sys_nice)
        assert _cycle_thread(node.proc.pid) == (os.SCHED_OTHER, 0)
        assert ("ssi_cycle thread runs with normal scheduling: SCHED_FIFO 5 not permitted "
                "(needs CAP_SYS_NICE or an rtprio limit; cycle_priority 0 skips this)") in node.log()
        assert _bus_value(probe, node, "cycle_scheduling") == "normal"
        assert _bus_value(probe, node, "receive_scheduling") == "normal"
        seen = probe.subscribe(JointState, node.topic("joint_states"), qos=100)
        probe.wait_for(lambda: len(seen) >= 50, 10.0, "joint_states with normal scheduling", node)
        assert node.stop() == 0

    node = running({"cycle_priority": 0, "diagnostics_period": 0.5})
    assert _cycle_thread(node.proc.pid) == (os.SCHED_OTHER, 0)
    assert _bus_value(probe, node, "cycle_scheduling") == "normal"
    assert "ssi_cycle thread runs with normal scheduling" not in node.log()
