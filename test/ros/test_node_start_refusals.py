"""Every start the node cannot run is refused: exit 1, the reason, no traceback.

One table, one node start per case (the installed executable: the refusal is its exit code and
its output, a process boundary). The cases came from the files of each concern (docs/testing.md
lists where): a REG_PARA1 the module would refuse with ERR_PARA (000 Table 19: SSI_FRAME_LEN
1..32, a reserved SSI_BIT_RATE, INVALID_BITS_MSB + INVALID_BITS_LSB < SSI_FRAME_LEN, reserved
bits 0), an encoder family no preset has, a family/override pair the simulated station cannot
build (001 §5.2.4.2: at most 16 step bits in the check sum format), a code the family does not
offer, joint names that clash with a status or a parameter, params files that cannot be read,
renamed parameters, station lists that do not fit the joints, values out of range, modes that
exclude each other, a station that never answers.

Where a case says ``one_line``, the node's whole output is the one refusal line; ``prefix``:
that line starts ``ssi_bridge_node: cannot start:``; ``no_bank``: the simulated station's
retentive bank (written as soon as a simulated module exists) was never created, so the
refusal came before any side effect (before, the bad joints were refused only after the
station process had started and the gateway was configured: 4-7 log lines came first).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
import yaml

PREFIX = "ssi_bridge_node: cannot start:"


@dataclass(frozen=True)
class Refusal:
    """One start the node refuses: its parameters and what its output must say."""

    params: dict[str, Any] = field(default_factory=dict)
    #: words the output holds (every one)
    words: tuple[str, ...] = ()
    #: the text of a --params-file given before the test's own ("" none; None: a missing file)
    params_file: str | None = ""
    args: tuple[str, ...] = ()
    one_line: bool = False
    prefix: bool = False
    no_bank: bool = False


def _qos(overrides: dict) -> str:
    return yaml.safe_dump({"/**": {"ros__parameters": {"qos_overrides": overrides}}})


BAD_JOINT = dict(one_line=True, prefix=True, no_bank=True)
CASES = {
    # a bad joint, before any side effect (test_node_start_refusals.py)
    "para1_frame_len": Refusal({"joint1.para1": 0x21010000},
                               ("joint1.para1 0x21010000 is invalid: SSI_FRAME_LEN = 33",),
                               **BAD_JOINT),
    "para1_bit_rate": Refusal({"joint1.para1": 0x19080000}, ("SSI_BIT_RATE = 8 is reserved",),
                              **BAD_JOINT),
    "para1_invalid_bits": Refusal({"joint1.para1": 0x05000500},
                                  ("INVALID_BITS_MSB + INVALID_BITS_LSB = 5",), **BAD_JOINT),
    "para1_reserved_bits": Refusal({"joint1.para1": 0x19010001}, ("reserved bits",),
                                   **BAD_JOINT),
    "unknown_family": Refusal({"joint1.family": "AFM60_MULTY"},
                              ("joint1.family 'AFM60_MULTY': unknown encoder family",),
                              **BAD_JOINT),
    "second_joint_family": Refusal({"joints": ["a", "b"], "b.family": "NOPE",
                                    "b.para1": 0x21010000}, ("b.family 'NOPE'",), **BAD_JOINT),
    "checksum_steps": Refusal({"joint1.family": "TR_CHECKSUM", "joint1.steps_per_rev": 131072},
                              ("131072 steps do not fit 16 singleturn bits",), **BAD_JOINT),
    # simulation off: no station to start, but the master would have opened the bus and
    # configured the gateway before refusing; nobody serves this channel
    "para1_real_hardware": Refusal({"simulation.enabled": False, "joint1.para1": 0x21010000},
                                   ("SSI_FRAME_LEN = 33",), one_line=True),
    # test_node_params.py
    "station_silent": Refusal({"simulation.enabled": False, "bus.sdo_timeout": 0.3},
                              ("cannot start", "node 1 did not answer within 0.300 s")),
    # `joints: [y]` is a YAML 1.1 boolean array, not names: a type error, said in one line
    "joints_not_names": Refusal({"joints": [True]}, ("cannot start", "joints")),
    "duplicate_slots": Refusal({"joints": ["a", "b"], "a.slot": 2, "b.slot": 2},
                               ("share a module slot",)),
    # 001 §5.2.4.2: the TR check-sum encoder sends binary only: the line names what it offers
    "code_not_offered": Refusal({"joints": ["a"], "a.family": "TR_CHECKSUM", "a.code": "gray"},
                                ("cannot start", "binary"), one_line=True),
    # /diagnostics names '<node>: <joint>', '<node>: bus', '<node>: station <id>'
    "joint_named_bus": Refusal({"joints": ["bus"]}, ("joint name 'bus'",), one_line=True),
    "joint_named_station": Refusal({"joints": ["station 3"]}, ("joint name 'station 3'",),
                                   one_line=True),
    # test_node_logs.py: the params file itself
    "params_file_missing": Refusal(words=("No such file",), params_file=None, one_line=True,
                                   prefix=True),
    "params_file_not_yaml": Refusal(words=("not valid YAML",),
                                    params_file="/**:\n  ros__parameters:\n    joints: [a\n",
                                    one_line=True, prefix=True),
    "params_file_not_mapping": Refusal(words=("expected a mapping",), params_file="- 1\n- 2\n",
                                       one_line=True, prefix=True),
    "params_file_no_joints": Refusal(words=("joints is empty",),
                                     params_file="/**:\n  ros__parameters:\n    joints: []\n",
                                     one_line=True, prefix=True),
    # test_node_qos.py
    "qos_unknown_policy": Refusal(
        words=("cannot start: qos_overrides of /joint_states: Unexpected QoS override for "
               "policy `reliability`: `bogus` (reliability: reliable | best_effort",),
        params_file=_qos({"/joint_states": {"publisher": {"reliability": "bogus"}}})),
    # test_node_param_dump.py: the old name, in a params file and on the command line
    "old_name_params_file": Refusal({"simulation": False}, ("'simulation'", "simulation.enabled"),
                                    one_line=True),
    "old_name_command_line": Refusal(args=("-p", "simulation:=false"),
                                     words=("'simulation'", "simulation.enabled"),
                                     one_line=True),
    # ``publish_rate.slot`` beside ``publish_rate``: the parameter dump could not nest them
    **{f"joint_prefix_{joint}": Refusal({"joints": sorted({"a", joint})},
                                        ("prefix", "name the joint"), one_line=True)
       for joint in ("publish_rate", "use_sim_time", "a.slot")},
    # test_node_split.py, test_node_liveview.py
    "split_size": Refusal({"record.max_size": 1000},
                          ("cannot start", "record.max_size 1000", "65536")),
    "foxglove_port": Refusal({"foxglove.port": 70000}, ("cannot start", "foxglove.port")),
    # test_node_replay.py
    "replay_missing_log": Refusal({"simulation.enabled": False,
                                   "replay.can_log": "/nowhere/none.log"},
                                  ("does not exist",)),
    "listen_only_simulated": Refusal({"bus.listen_only": True},
                                     ("bus.listen_only needs simulation.enabled:=false",)),
    "replay_simulated": Refusal({"replay.can_log": "/nowhere/can_0.log"},
                                ("replay.can_log needs simulation.enabled:=false",)),
    # test_node_stations.py
    "station_not_listed": Refusal({"joints": ["a", "b"], "stations": [1, 3], "a.station": 1,
                                   "b.station": 5}, ("b.station 5: not one of stations [1, 3]",)),
    "station_without_joint": Refusal({"joints": ["a"], "stations": [1, 3]},
                                     ("stations [3] hold no joint",)),
    "stations_share_slot": Refusal({"joints": ["a", "b"], "stations": [1, 3], "a.station": 3,
                                    "b.station": 3, "a.slot": 1, "b.slot": 1},
                                   ("share a module slot",)),
    "stations_not_unique": Refusal({"joints": ["a"], "stations": [1, 1]},
                                   ("unique CANopen node ids",)),
}


@pytest.mark.parametrize("case", CASES.values(), ids=CASES.keys())
def test_a_start_the_node_cannot_run_is_refused(start_node, tmp_path: Path, case: Refusal):
    bank = tmp_path / "bank_refused" / "retentive.json"
    params_file = None
    if case.params_file is None:
        params_file = tmp_path / "missing.yaml"
    elif case.params_file:
        params_file = tmp_path / "given.yaml"
        params_file.write_text(case.params_file)
    node = start_node({**case.params, "storage_path": str(bank)}, params_file=params_file,
                      args=case.args)
    assert node.proc.wait(60) == 1, node.log()
    log = node.log()
    assert all(w in log for w in case.words), log[-3000:]
    assert "Traceback" not in log, log[-3000:]
    lines = [line for line in log.splitlines() if line.strip()]
    if case.one_line:
        assert len(lines) == 1, "more than the refusal:\n" + log
    if case.prefix:
        assert lines[0].startswith(PREFIX), lines
    if case.no_bank:
        assert not bank.parent.exists(), "the simulated station was started"
