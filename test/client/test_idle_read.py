"""A register read sets REG_RD_ADR back to the address it found (the node's idle read).

000 "Internal registers": REG_RD_DATA of the process input shows the
register that REG_RD_ADR (process output byte 4) names, in every cycle, and the input echoes
REG_RD_ADR. The node keeps REG_RD_ADR at REG_SSI_FRAME (33) while no handshake runs, so its
frame checks (parity, filler, check sum, PowerFail, encoder error bit) read the raw frame
every cycle (docs/node.md). Before, the handshake left REG_RD_ADR at the register it read, and
the checks stayed off until the node restarted. Real master and simulated station on a
private virtual bus.
"""

from __future__ import annotations

import time

import pytest

from ssi_bridge.client.master import BridgeClient
from ssi_bridge.exceptions import RegisterReadError
from ssi_bridge.protocol.images import ProcessInput
from ssi_bridge.protocol.registers import Reg
from ssi_bridge.sim.gateway.gateway import XnGateway

IDLE = int(Reg.REG_SSI_FRAME)  # 33


def _idle_read(out: bytearray) -> None:
    out[4] = IDLE  # what ros/messages.idle_read sends at start-up


def _echoed_address(client: BridgeClient, cycles: int = 1) -> int:
    """REG_RD_ADR echoed in the input image after ``cycles`` more SYNC cycles."""
    for _ in range(cycles):
        client.sync()
        assert client.wait_cycle(0.5)
    sample = client.latest(1)
    assert sample is not None
    return ProcessInput.decode(sample.process_input).reg_rd_adr


@pytest.mark.parametrize("address", [int(Reg.REG_PARA1), int(Reg.REG_SSI_MASK),
                                     int(Reg.REG_SSI_POS)])
def test_a_register_read_sets_the_idle_read_address_back(
        station: tuple[XnGateway, BridgeClient, list], address: int) -> None:
    """After ``read_register`` the output carries REG_RD_ADR = 33 again, and the input
    echoes it in the next cycle (the read returns once the echo came)."""
    _, client, _ = station
    client.edit_output(1, _idle_read)
    assert _echoed_address(client, 3) == IDLE
    client.read_register(1, address)
    assert client.table.slot(1).output[4] == IDLE
    started = time.monotonic()
    assert _echoed_address(client) == IDLE
    assert time.monotonic() - started < 0.5


def test_a_refused_read_sets_the_idle_read_address_back(
        station: tuple[XnGateway, BridgeClient, list]) -> None:
    """A read the module refuses (REG_RD_ABORT = 1, a reserved address) restores it too."""
    _, client, _ = station
    client.edit_output(1, _idle_read)
    assert _echoed_address(client, 3) == IDLE
    with pytest.raises(RegisterReadError):
        client.read_register(1, 63)
    assert client.table.slot(1).output[4] == IDLE
    assert _echoed_address(client, 2) == IDLE
