"""The numpy batch path reads the same bits as the scalar line (004 §2.2, 001 §4.6)."""

from __future__ import annotations

import numpy as np
import pytest

from ssi_bridge.protocol.codes import Code
from ssi_bridge.sim.encoder.encoder import make_encoder
from ssi_bridge.sim.encoder.motion import ConstantVelocity, Sine
from ssi_bridge.sim.line.batch import read_batch
from ssi_bridge.sim.line.line import LineConfig, SsiLine


@pytest.mark.parametrize("family, kw, n_extra", [
    ("GENERIC", {}, 0), ("GENERIC", {"code": Code.GRAY}, 0), ("AHM36_MULTI", {}, 0),
    ("AFS60", {}, 0), ("TTK70", {}, 3), ("ATM60", {"steps_per_rev": 1000}, 0),
    ("GENERIC", {}, -2),
    # 001 §5.2.4.2's example: 4096 x 1024 steps = 22 data bits, 28-bit field + 15 check sum bits
    ("TR_CHECKSUM", {"revolutions_numerator": 1024, "data_bits": 22}, 0),
])
def test_batch_equals_scalar(family, kw, n_extra) -> None:
    """Same frames, pause-1, extra zero clocks and ZERO-test level as SsiLine.read."""
    motion = Sine(3.0, 2.0, offset=5.0) if not family.startswith("TTK") else ConstantVelocity(0.3, 0.1)
    enc = make_encoder(family, motion, **kw)
    n = enc.frame_bits + n_extra
    times = np.arange(200) * 1e-3 + 0.1234e-3
    batch = read_batch(SsiLine(enc, LineConfig(check_cable_table=False)), times, n, 1e6)
    line = SsiLine(make_encoder(family, motion, **kw), LineConfig(check_cable_table=False))
    for i, t in enumerate(times):
        r = line.read(float(t), n, 1e6)
        assert (int(batch.data[i]), int(batch.start_bit[i]), int(batch.trailer_bit[i])) == \
            (r.data, r.start_bit, r.trailer_bit), f"burst {i}"


def test_batch_faults() -> None:
    """Data wire break reads LOW (003 SB.0); clock break reads idle high (003 SB.1)."""
    line = SsiLine(make_encoder("GENERIC", ConstantVelocity(1.0)))
    line.faults.data_break = True
    b = read_batch(line, np.zeros(4), 25, 1e6)
    assert not b.start_bit.any() and not b.data.any()
    line.faults.clear()
    line.faults.clock_break = True
    b = read_batch(line, np.zeros(4), 25, 1e6)
    assert b.trailer_bit.all() and (b.data == (1 << 25) - 1).all()
