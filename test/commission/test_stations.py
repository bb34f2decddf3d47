"""The tool against simulated stations whose configuration it is not told.

Every encoder of the manuals (conftest.VARIANTS: 004 §3.1-§3.7, 001 §5, 003) sits on random
slots of 1-2 gateways at random node ids; the tool's result is checked against the hidden
truth: every gateway and XN-1SSI module found, REG_PARA1 exactly as the module holds it
(000 Table 19), the true family first where the frame tells the families apart and among the
first-ranked elsewhere (a tie only between layouts whose position LSB sits at the same frame
bit), the code and the count direction of the moving encoder, and a params file whose joints
the node's own parameter reader accepts with the family the tool chose; REG_RD_ADR is back
at what a previous master left in every output image (000 "Internal registers").
"""

from __future__ import annotations

import io
import random

import pytest

from ssi_bridge.commission.infer import MotionState
from ssi_bridge.commission.params_out import BusSpec, joint_name, render
from ssi_bridge.commission.rank import layout_of
from ssi_bridge.commission.run import Options, Result, commission
from ssi_bridge.protocol.joint_encoder import joint_config
from ssi_bridge.protocol.para1 import Para1
from ssi_bridge.protocol.settings import (JOINT_DEFAULTS, BusConfig, JointSettings,
                                          joint_from_values, load_params_file)

from .conftest import VARIANTS, Truth, leave_outputs, random_layout, read_addresses

#: sampling time of a run (s); the tool samples on, up to ten times as long, until each slot
#: has 30 samples (sample.MIN_SAMPLES, MAX_SECONDS_FACTOR)
SECONDS = 1.0
#: REG_RD_ADR a previous master left in the output images (REG_SW_VER)
READ_ADDRESS = 3


def run(truth: Truth, seconds: float = SECONDS) -> Result:
    """The tool on the stations' bus, narrowed to nothing: all 127 node ids are scanned."""
    return commission(BusConfig("udp_multicast", truth.channel),
                      Options(seconds=seconds, sdo_timeout=0.5))


def check_against(truth: Truth, result: Result) -> None:
    """Assert the tool found what the stations hold (module docstring)."""
    assert result.refusal is None
    found = {st.identity.node_id: st for st in result.stations}
    assert set(found) == set(truth.stations), (set(found), set(truth.stations))
    for node_id, station in found.items():
        ssi = [p.slot for p in station.probes if p.para1 is not None]
        assert ssi == list(range(1, truth.modules[node_id] + 1)), (node_id, ssi)
        for res in station.slots:
            joint = truth.joint(node_id, res.slot)
            where = f"node {node_id} slot {res.slot}"
            if joint is None:  # a module with no encoder on its line
                assert not res.joint and res.problem, (where, res.problem)
                continue
            family = joint.settings.family
            assert res.para1 == joint.para1, (where, hex(res.para1 or 0), hex(joint.para1))
            assert res.joint, (where, family, res.problem, res.warnings)
            top = res.groups[0]
            names = [f.family for f in top]
            assert family in names, (where, family, [[f.family for f in g] for g in res.groups])
            frame_len = Para1.decode(joint.para1).ssi_frame_len
            truth_lsb = layout_of(joint.config, frame_len).lsb
            for fit in top:  # a tie only where the frame cannot tell the layouts apart
                assert layout_of(fit.config, frame_len).lsb == truth_lsb, \
                    (where, family, fit.family, res.samples, res.motion)
            motion = res.motion
            assert motion is not None and motion.state is MotionState.MOVING, \
                (where, family, motion)
            assert motion.code == joint.settings.code, (where, family, motion.code)
            assert motion.direction == joint.direction, (where, family, motion.evidence)
    check_params_file(truth, result)


def check_params_file(truth: Truth, result: Result) -> None:
    """The params file is read by the node's own parameter reader with the tool's choices."""
    text = render(BusSpec("udp_multicast", truth.channel, 500_000), result.slot_results)
    values = load_params_file(io.StringIO(text))
    made = {}
    for name in values["joints"]:  # the reader of '<joint>.*' the node and the station share
        jv = {key: values.get(f"{name}.{key}", d) for key, d in JOINT_DEFAULTS.items()}
        made[name] = joint_from_values(name, jv, slot=int(jv["slot"]),
                                       station=int(values[f"{name}.station"]))
    for res in result.slot_results:
        if not res.joint:
            assert joint_name(res) not in made
            continue
        joint: JointSettings = made[joint_name(res)]
        assert (joint.station, joint.slot, joint.para1) == (res.node_id, res.slot,
                                                            res.para1_joint)
        assert joint.family == res.best.family
        assert joint_config(joint).frame_bits == res.best.config.frame_bits
    assert sorted(values["stations"]) == sorted(truth.stations)


@pytest.mark.parametrize("seed, gateways", [(1, 2), (2, 2), (3, 1)])
def test_every_family_of_the_manuals_on_random_slots_and_node_ids(stations, seed, gateways):
    """Seeds 1 and 2 split the 21 variants (8 + 8 joints over two gateways); seed 3 the rest
    on one gateway, so every variant is commissioned once in the fast tier."""
    rng = random.Random(seed)
    variants = list(VARIANTS)
    rng.shuffle(variants)
    chunk = {1: variants[:8], 2: variants[8:16], 3: variants[16:]}[seed]
    # two gateways hold at most 8 joints each; the first 16 variants fill two runs
    truth = stations(random_layout(rng, chunk, gateways))
    leave_outputs(truth, READ_ADDRESS)
    result = run(truth)
    check_against(truth, result)
    # the read handshake set REG_RD_ADR back to what the previous master had left
    assert set(read_addresses(truth).values()) == {READ_ADDRESS}


@pytest.mark.parametrize("seed", range(10, 20))
def test_random_stations_sweep(stations, seed):
    """Slow tier: random draws of 1-8 joints over 1-2 gateways, families with repetition."""
    rng = random.Random(seed)
    gateways = rng.choice((1, 2))
    chosen = [rng.choice(VARIANTS) for _ in range(rng.randint(1, 8))]
    truth = stations(random_layout(rng, chosen, gateways))
    check_against(truth, run(truth))
