"""Liveness measured on the bus: a stalled receive thread is not a silent gateway;
a gateway that really stops sending is still found silent, and never before the timeout."""

from __future__ import annotations

import time

import can

from ssi_bridge.gateway.bus import BusConfig, open_bus
from ssi_bridge.gateway.timebase import wire_now

STALL_COB = 0x123


def test_a_stalled_receive_thread_is_not_a_silent_gateway(station, channel) -> None:
    gateway, client, _ = station
    stall_s = 3 * client.heartbeat_timeout
    client.network.subscribe(STALL_COB, lambda *_: time.sleep(stall_s))
    poke = open_bus(BusConfig(channel=channel, node_id=5))
    try:
        assert client.gateway_alive
        poke.send(can.Message(arbitration_id=STALL_COB, data=b"", is_extended_id=False))
        # while the client's receive thread sleeps, the gateway's heartbeats queue up with
        # their arrival times: the wire never went quiet, so the gateway is never "silent"
        end = time.monotonic() + stall_s + 0.5
        seen_false = 0
        while time.monotonic() < end:
            seen_false += not client.gateway_alive
            time.sleep(0.005)
        assert seen_false == 0, f"gateway reported silent {seen_false} times during a stall"
    finally:
        poke.shutdown()


def test_a_really_silent_gateway_is_found_after_the_timeout(station) -> None:
    gateway, client, _ = station
    assert client.gateway_alive
    muted_at = wire_now()
    gateway.silent = True
    deadline = time.monotonic() + 5.0
    while client.gateway_alive and time.monotonic() < deadline:
        time.sleep(0.005)
    found = wire_now()
    assert not client.gateway_alive, "a silent gateway was never found silent"
    # the decision rests on bus evidence: the last heartbeat is older than the timeout in
    # the wire time the receive thread has seen, and it came before the mute
    last = client._liveness.last_heartbeat
    assert last <= muted_at + 0.01
    assert client.bus.seen_until() - last > client.heartbeat_timeout
    assert found - muted_at >= client.heartbeat_timeout - 0.06  # never before the timeout
    gateway.silent = False
    deadline = time.monotonic() + 5.0
    while not client.gateway_alive and time.monotonic() < deadline:
        time.sleep(0.005)
    assert client.gateway_alive
