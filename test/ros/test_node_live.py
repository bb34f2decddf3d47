"""One truth for REG_PARA1 and live parameters, against the installed node.

REG_PARA1 (000 Table 18/19) sets how the XN-1SSI reads the frame: INVALID_BITS_LSB = 1 shifts
one bit out, so REG_SSI_POS counts half as fine (docs/node.md, Units). Whichever path changes
it — the ``<joint>.para1`` parameter, ``~/write_register`` to address 20, or REG_SF "LD20"
which restores the defaults including REG_PARA1 (000 "Resetting the register bank") — the
published position must stay the shaft's and the velocity the profile's.
"""

from __future__ import annotations

import math
import time

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import GetParameters, SetParameters
from sensor_msgs.msg import JointState
from ssi_bridge_msgs.msg import Event
from ssi_bridge_msgs.srv import ReadRegister, ResetRegisters, WriteRegister

SPEED = 2 * math.pi * 0.25  # the default simulated shaft: 0.25 rev/s = 1.571 rad/s
PARA1_DEFAULT = 0x19010000  # 000 Table 19: 25-bit frame, 500 kbit/s, binary
PARA1_LSB1 = 0x19010100  # the same with INVALID_BITS_LSB = 1: half the counts per turn


def _value(value):
    if isinstance(value, bool):
        return ParameterValue(type=ParameterType.PARAMETER_BOOL, bool_value=value)
    if isinstance(value, int):
        return ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=value)
    if isinstance(value, float):
        return ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=value)
    return ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=value)


def _set(probe, node, name, value):
    req = SetParameters.Request(parameters=[Parameter(name=name, value=_value(value))])
    return probe.call(SetParameters, node.topic("~/set_parameters"), req).results[0]


def _get(probe, node, name):
    res = probe.call(GetParameters, node.topic("~/get_parameters"),
                     GetParameters.Request(names=[name]))
    v = res.values[0]
    return {ParameterType.PARAMETER_INTEGER: v.integer_value,
            ParameterType.PARAMETER_DOUBLE: v.double_value,
            ParameterType.PARAMETER_STRING: v.string_value}.get(v.type)


def _stamp(msg) -> float:
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


def _line(samples):
    """Least-squares position = a + v * stamp over (stamp, position) pairs."""
    n = len(samples)
    mt = sum(t for t, _ in samples) / n
    mp = sum(p for _, p in samples) / n
    v = sum((t - mt) * (p - mp) for t, p in samples) / sum((t - mt) ** 2 for t, _ in samples)
    return lambda t: mp + v * (t - mt), v


def _change(probe, node, path):
    if path == "parameter":
        res = _set(probe, node, "joint1.para1", PARA1_LSB1)
        assert res.successful, res.reason
        return PARA1_LSB1
    if path == "write_register":
        res = probe.call(WriteRegister, node.topic("~/write_register"),
                         WriteRegister.Request(address=20, value=PARA1_LSB1))
        assert res.success, res.message
        assert "joint1.para1" in res.message, res.message
        return PARA1_LSB1
    res = probe.call(ResetRegisters, node.topic("~/reset_registers"),
                     ResetRegisters.Request(include_parameters=True))
    assert res.success, res.message
    assert f"0x{PARA1_DEFAULT:08X}" in res.message, res.message
    return PARA1_DEFAULT


@pytest.mark.parametrize("path", ["parameter", "write_register", "reset_ld20"])
def test_every_reg_para1_path_keeps_position_and_velocity_true(running, probe, path):
    start_para1 = PARA1_LSB1 if path == "reset_ld20" else PARA1_DEFAULT
    node = running({"joint1.para1": start_para1, "joint1.motion.start": 0.3})
    msgs = probe.subscribe(JointState, node.topic("joint_states"), qos=1000)
    probe.wait_for(lambda: len(msgs) >= 40, 10.0, "40 joint_states before the change", node)
    before = [(_stamp(m), m.position[0]) for _, m in msgs[5:]]
    truth, speed = _line(before)
    assert speed == pytest.approx(SPEED, rel=0.01), "the shaft turns at the profile speed"
    t_change = time.monotonic()
    expected = _change(probe, node, path)
    assert _get(probe, node, "joint1.para1") == expected, "the parameter follows the module"
    back = probe.call(ReadRegister, node.topic("~/read_register"), ReadRegister.Request(address=20))
    assert back.success and back.value == expected
    count = len(msgs)
    probe.wait_for(lambda: len(msgs) >= count + 40, 10.0, "40 joint_states after the change", node)
    after = [m for t, m in msgs if t >= t_change]
    known = [m for m in after if not math.isnan(m.position[0])]
    assert len(known) >= 30, "a change leaves at most the samples of its handshake unknown"
    tolerance = 0.02  # rad: a few counts plus stamp noise
    worst = max(abs(m.position[0] - truth(_stamp(m))) for m in known)
    assert worst < tolerance, (f"{path}: a published position left the shaft's by {worst:.3f} "
                               "rad (REG_PARA1 and the scale disagreed)")
    v = [m.velocity[0] for m in after[-20:] if not math.isnan(m.velocity[0])]
    assert v and max(abs(x - SPEED) for x in v) < 0.05 * SPEED, \
        f"{path}: velocity {v[-1] if v else None} instead of the profile's {SPEED:.3f} rad/s"
    # right after the restart the estimate spans one period: docs/node.md's bound is one count
    # over the span, 2 pi / 4096 rad / 10 ms = 0.15 rad/s at the coarser REG_PARA1 (a scale
    # left behind would be off by the whole speed, 1.57 rad/s)
    bound = 2 * math.pi / 4096 / 0.01 + 0.02 * SPEED
    jumps = [m.velocity[0] for m in after if not math.isnan(m.velocity[0])]
    assert max(abs(x - SPEED) for x in jumps) < bound, "no velocity spike at the change"


def test_ld20_on_a_gray_encoder_says_the_default_does_not_fit_and_warns(running, probe):
    # shoulder as in config/ssi_bridge.yaml: AFM60 multiturn in Gray; LD20 restores the
    # binary default REG_PARA1, which misreads the Gray frame: say so, and WARN
    node = running({"joints": ["shoulder"], "shoulder.family": "AFM60_MULTI",
                    "shoulder.code": "gray", "shoulder.steps_per_rev": 32768,
                    "shoulder.para1": 0x9E010300, "diagnostics_period": 0.5})
    diags = probe.subscribe(DiagnosticArray, "/diagnostics")
    res = probe.call(ResetRegisters, node.topic("~/reset_registers"),
                     ResetRegisters.Request(joint="shoulder", include_parameters=True))
    assert res.success, res.message
    assert "does not fit" in res.message and "gray" in res.message, res.message
    assert _get(probe, node, "shoulder.para1") == PARA1_DEFAULT

    def warned():
        for _, arr in reversed(diags):
            for st in arr.status:
                if st.name == "/ssi_bridge: shoulder":
                    return st.level >= b"\x01" and "does not fit" in st.message
        return False
    probe.wait_for(warned, 5.0, "shoulder WARN: REG_PARA1 does not fit the encoder", node)
    good = _set(probe, node, "shoulder.para1", 0x9E010300)
    assert good.successful, good.reason


def test_every_runtime_parameter_takes_effect_and_every_change_is_an_event(running, probe):
    node = running({"publish_rate": 100.0, "diagnostics_period": 0.5})
    msgs = probe.subscribe(JointState, node.topic("joint_states"))
    diags = probe.subscribe(DiagnosticArray, "/diagnostics")
    events = probe.subscribe(Event, node.topic("~/events"))
    probe.wait_for(lambda: len(diags) > 0, 5.0, "diagnostics", node)

    def joint_values():
        for _, arr in reversed(diags):
            for st in arr.status:
                if st.name == "/ssi_bridge: joint1":
                    return {kv.key: kv.value for kv in st.values}
        return {}

    def bus_values():
        for _, arr in reversed(diags):
            for st in arr.status:
                if st.name == "/ssi_bridge: bus":
                    return {kv.key: kv.value for kv in st.values}
        return {}

    changes = {"frame_id": "base_link", "velocity_window": 20, "stale_cycles": 7,
               "publish_rate": 50.0, "diagnostics_period": 0.25, "joint1.max_speed": 100.0}
    for name, value in changes.items():
        res = _set(probe, node, name, value)
        assert res.successful, (name, res.reason)
    # frame_id: the next messages carry it
    count = len(msgs)
    probe.wait_for(lambda: len(msgs) > count + 5, 5.0, "joint_states after the changes", node)
    assert msgs[-1][1].header.frame_id == "base_link"
    # diagnostics show every current value (and come at the new period)
    probe.wait_for(lambda: joint_values().get("velocity_window") == "20", 5.0,
                   "velocity_window 20 in diagnostics", node)
    jv = joint_values()
    assert jv["stale_limit_cycles"] == "7" and jv["frame_id"] == "base_link"
    assert float(jv["max_speed"]) == 100.0
    probe.wait_for(lambda: bus_values().get("publish_rate_hz") == "50.00", 5.0,
                   "publish_rate 50 in the bus diagnostics", node)
    assert bus_values()["diagnostics_period_s"] == "0.25"
    n0, t0 = len(diags), time.monotonic()
    time.sleep(2.0)
    period = (time.monotonic() - t0) / max(1, len(diags) - n0)
    assert period < 0.4, f"diagnostics every {period:.2f} s after setting 0.25 s"
    # velocity_window: the estimate restarted with the new window and is the profile speed
    assert abs(msgs[-1][1].velocity[0] - SPEED) < 0.05 * SPEED
    # every change, and every refusal, is an ~/events record
    refused = _set(probe, node, "bus.node_id", 5)
    assert not refused.successful
    out_of_range = _set(probe, node, "velocity_window", 1)
    assert not out_of_range.successful
    probe.wait_for(lambda: sum(e.kind == "set_parameters" for _, e in events) >= len(changes) + 2,
                   5.0, "an event per parameter change and refusal", node)
    texts = [(e.request, e.success, e.message) for _, e in events if e.kind == "set_parameters"]
    for name in changes:
        assert any(r.startswith(f"{name}=") and ok for r, ok, _ in texts), (name, texts)
    assert any(r.startswith("bus.node_id=") and not ok and "refused" in m
               for r, ok, m in texts), texts
    assert any(r.startswith("velocity_window=") and not ok for r, ok, _ in texts), texts
