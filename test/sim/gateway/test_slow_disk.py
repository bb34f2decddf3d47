"""A slow disk does not silence the simulated station.

A retentive register (REG_PARA1, 000 "Storage in module") is saved before the write takes
effect and only then answered over SDO (object 0x5801, 000 Table 16). Beside a busy test
suite an fsync on this machine's disk took up to 5.7 s, longer than the master's SDO timeout:
the station's banks (``SimStation._store``) save by atomic replace without fsync, so the
answer does not wait on the disk, and the bank on disk holds the new value at once.
"""

from __future__ import annotations

import os
import time


from ssi_bridge.protocol.registers import Reg
from ssi_bridge.protocol.settings import BusConfig
from ssi_bridge.sim.gateway.gateway import XnGateway
from ssi_bridge.sim.gateway.station import SimStation
from ssi_bridge.sim.module.store import RetentiveStore
from ssi_bridge.sim.module.xn1ssi import Xn1Ssi

from support.virtual_bus import ScriptedReader

from .conftest import NODE_ID, canopen_master

SLOW_FSYNC_S = 2.0
#: another REG_PARA1 the module accepts: 25 data bits, Gray (000 Table 19)
PARA1 = 0x19020000


def test_a_reg_para1_write_is_answered_without_waiting_on_the_disk(channel, tmp_path,
                                                                   monkeypatch) -> None:
    synced: list[int] = []

    def slow_fsync(fd: int) -> None:
        # only the station's own files count: another thread of this test process (a
        # previous test's station still stopping, on a busy machine) may sync a file of its own
        try:
            path = os.readlink(f"/proc/self/fd/{fd}")
        except OSError:
            path = ""
        if path.startswith(str(tmp_path)):
            synced.append(fd)
        time.sleep(SLOW_FSYNC_S)

    monkeypatch.setattr(os, "fsync", slow_fsync)
    store = SimStation._store(str(tmp_path / "retentive.json"), 1)
    gateway = XnGateway(BusConfig(channel=channel, node_id=NODE_ID), NODE_ID,
                        [Xn1Ssi(ScriptedReader(1000), slot=1, store=store)])
    gateway.start()
    try:
        with canopen_master(channel, 1, sdo_timeout=1.0) as (_, node):
            start = time.monotonic()
            node.sdo[0x5801][1].raw = PARA1
            answered = time.monotonic() - start
            assert node.sdo[0x5801][1].raw == PARA1
    finally:
        gateway.stop()
    assert answered < SLOW_FSYNC_S / 2, f"the SDO answer took {answered:.2f} s"
    assert synced == [], "the station's bank is saved without fsync"
    saved = RetentiveStore(store.path).load()
    assert saved is not None and saved.values[Reg.REG_PARA1] == PARA1, "on disk at once"
