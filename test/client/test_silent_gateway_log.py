"""A silent gateway is said quietly: one line when it goes silent, one when it is heard again,
and at most one summary per SILENT_SUMMARY_S between; the SDO probes that find it silent do
not log each unanswered transfer. Before: canopen logged two lines (a missing response and
the transfer aborted) for each probe, about eight a second, for as long as the silence lasted.
"""

from __future__ import annotations

import logging
import time

from ssi_bridge.client import liveness

from .conftest import wait_until


def _lines(caplog, text: str) -> int:
    return sum(text in r.getMessage() for r in caplog.records)


def test_a_silent_gateway_is_one_line_then_one_when_back(station, caplog, monkeypatch):
    gateway, client, _ = station
    monkeypatch.setattr(liveness, "SILENT_SUMMARY_S", 1.0)  # a summary within the test
    caplog.set_level(logging.DEBUG)
    gateway.silent = True
    muted = time.monotonic()
    # three probes unanswered and a summary due: by the supervisor's own counts, as fast as
    # this machine lets it probe (each probe waits the fixture's SDO timeout)
    wait_until(lambda: client.counters.timeouts >= 3 and _lines(caplog, "still silent") >= 1,
               "three unanswered probes and a summary of the silence", timeout=30.0)
    silent_for = time.monotonic() - muted
    assert not client.gateway_alive
    sdo = [r for r in caplog.records if r.name == "canopen.sdo.client"]
    assert sdo == [], [r.getMessage() for r in sdo]
    assert _lines(caplog, "silent: no heartbeat") == 1
    # at most one per summary period, the first one period into the silence
    assert _lines(caplog, "still silent") <= silent_for // liveness.SILENT_SUMMARY_S
    gateway.silent = False
    # the next supervisor round says so; a loaded machine may first finish the probe that
    # found the gateway and the re-configuration it asked for
    wait_until(lambda: _lines(caplog, "heard again after") >= 1, "'heard again'", timeout=30.0)
    assert client.gateway_alive
    time.sleep(0.2)
    assert _lines(caplog, "heard again after") == 1


def test_sdo_errors_outside_a_probe_are_still_logged(station, caplog):
    """The filter drops only the probe's lines: a user's transfer that fails is logged."""
    import pytest

    from ssi_bridge.exceptions import SsiBridgeError

    gateway, client, _ = station
    caplog.set_level(logging.DEBUG)
    gateway.silent = True
    with pytest.raises(SsiBridgeError) as raised:
        client.read_object(0x1000)
    # what failed it says why there is no line (a timeout is canopen's to log: a retry and the
    # abort; a bus that refused the request raises BusError before canopen waits at all)
    assert any(r.name == "canopen.sdo.client" for r in caplog.records), (
        f"{type(raised.value).__name__}: {raised.value}",
        [f"{r.name}: {r.getMessage()}" for r in caplog.records])
