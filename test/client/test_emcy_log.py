"""EMCY log summary: the first edge at once, then at most one line per second per slot, code
and diagnostics bit, each line saying how many edges it stands for (000 "Additional
emergencies": 0x7000 with module number in byte 3 and the diagnostics bit in byte 5)."""

from __future__ import annotations

import logging

from ssi_bridge.client.emcy_log import EmcySummary, describe


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def test_a_flapping_slot_is_one_line_per_second_per_code(caplog):
    clock = Clock()
    log = EmcySummary(logging.getLogger("test.emcy"), "gw ", clock=clock)
    caplog.set_level(logging.INFO, "test.emcy")
    ssi_error = bytes([1, 1, 0x02, 0, 0])  # slot 1, channel 1, bit 0x02 SSI error
    for step in range(300):  # 3 s of ~100 set/reset pairs a second
        clock.t = step / 100
        log.on_emcy(0x7000, ssi_error)
        log.on_emcy(0x0000, bytes(5))
    texts = [r.getMessage() for r in caplog.records]
    assert len(texts) == 6, texts  # 3 s x (set, reset)
    assert texts[0] == "gw EMCY 0x7000 slot 1: SSI error"
    assert texts[2] == "gw EMCY 0x7000 slot 1: SSI error (and 99 more in the last 1.0 s)"
    assert "error reset" in texts[1]


def test_other_slots_and_bits_are_not_hidden_behind_a_busy_one(caplog):
    clock = Clock()
    log = EmcySummary(logging.getLogger("test.emcy2"), clock=clock)
    caplog.set_level(logging.INFO, "test.emcy2")
    assert log.on_emcy(0x7000, bytes([1, 1, 0x02, 0, 0]))
    assert not log.on_emcy(0x7000, bytes([1, 1, 0x02, 0, 0]))
    assert log.on_emcy(0x7000, bytes([2, 1, 0x02, 0, 0])), "slot 2 has its own budget"
    assert log.on_emcy(0x7000, bytes([1, 1, 0x10, 0, 0])), "parameter error is another bit"
    assert "parameter error" in caplog.records[-1].getMessage()


def test_description_of_codes():
    assert describe(0x7000, bytes([3, 1, 0x04, 0, 0]))[1] == "EMCY 0x7000 slot 3: overflow"
    assert describe(0x8130, bytes(5))[1] == "EMCY 0x8130 data 0000000000"
