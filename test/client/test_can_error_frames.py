"""SocketCAN error frames decoded to the letter of linux/can/error.h, counted and understood.

The class bits (the error frame's identifier) and the data bytes are the header's: data[0]
lost-arbitration bit, data[1] controller status, data[2]/[3] protocol violation type and
location, data[4] transceiver status, data[6]/[7] TX/RX error counters; error states by
counter 0-95 active, 96-127 warning, 128-255 passive (the header's thresholds). Where the
header is installed its #define values are compared with the decoder's.
"""

from __future__ import annotations

import logging
import re
from pathlib import Path

import can
import pytest

from ssi_bridge.client.error_frames import ErrorFrameWatch, error_frame_keys
from ssi_bridge.protocol import can_errors as ce
from ssi_bridge.protocol.can_errors import decode_error_frame
from ssi_bridge.sim.gateway.error_frames import error_frame, error_frames

HEADER = Path("/usr/include/linux/can/error.h")
#: the header's class bits, as published (linux/can/error.h)
CLASSES = {"CAN_ERR_TX_TIMEOUT": 0x001, "CAN_ERR_LOSTARB": 0x002, "CAN_ERR_CRTL": 0x004,
           "CAN_ERR_PROT": 0x008, "CAN_ERR_TRX": 0x010, "CAN_ERR_ACK": 0x020,
           "CAN_ERR_BUSOFF": 0x040, "CAN_ERR_BUSERROR": 0x080, "CAN_ERR_RESTARTED": 0x100,
           "CAN_ERR_CNT": 0x200}


def test_the_class_bits_and_controller_bits_are_the_headers() -> None:
    for name, value in CLASSES.items():
        assert getattr(ce, name) == value, name
    assert (ce.CAN_ERR_CRTL_RX_WARNING, ce.CAN_ERR_CRTL_TX_WARNING, ce.CAN_ERR_CRTL_RX_PASSIVE,
            ce.CAN_ERR_CRTL_TX_PASSIVE, ce.CAN_ERR_CRTL_ACTIVE) == (0x04, 0x08, 0x10, 0x20, 0x40)
    assert ce.CAN_ERR_DLC == 8


@pytest.mark.skipif(not HEADER.exists(), reason="linux/can/error.h is not installed")
def test_every_define_the_decoder_uses_matches_the_installed_header() -> None:
    defines = {m.group(1): int(m.group(2), 16) for m in re.finditer(
        r"#define\s+(CAN_ERR_\w+)\s+0x([0-9A-Fa-f]+)U?", HEADER.read_text())}
    used = [n for n in dir(ce) if n.startswith("CAN_ERR_") and n != "CAN_ERR_DLC"]
    assert used and all(defines[n] == getattr(ce, n) for n in used), \
        {n: (defines.get(n), getattr(ce, n)) for n in used}
    for value, words in ce.PROT_LOCATIONS.items():
        assert value in defines.values(), words
    prot_types = {v for k, v in defines.items() if re.fullmatch(r"CAN_ERR_PROT_[A-Z01]+", k)
                  and k not in CLASSES and k != "CAN_ERR_PROT_UNSPEC"}
    assert set(ce.PROT_TYPES) == prot_types


def test_bus_off_and_the_restart() -> None:
    frame = decode_error_frame(0x040, bytes(8))
    assert frame.classes == ("bus_off",) and frame.state == ce.BUS_OFF
    assert decode_error_frame(0x100, bytes(8)).state == ce.ERROR_ACTIVE


@pytest.mark.parametrize("crtl, state", [(0x04, ce.ERROR_WARNING), (0x08, ce.ERROR_WARNING),
                                         (0x10, ce.ERROR_PASSIVE), (0x20, ce.ERROR_PASSIVE),
                                         (0x40, ce.ERROR_ACTIVE), (0x01, None)])
def test_the_controller_status_byte(crtl: int, state: str | None) -> None:
    frame = decode_error_frame(0x004, bytes([0, crtl, 0, 0, 0, 0, 0, 0]))
    assert frame.classes == ("controller",) and frame.state == state, frame


@pytest.mark.parametrize("tx, rx, state", [(0, 0, ce.ERROR_ACTIVE), (95, 0, ce.ERROR_ACTIVE),
                                           (96, 0, ce.ERROR_WARNING), (0, 127, ce.ERROR_WARNING),
                                           (128, 0, ce.ERROR_PASSIVE), (0, 255, ce.ERROR_PASSIVE)])
def test_the_error_counters_and_their_thresholds(tx: int, rx: int, state: str) -> None:
    frame = decode_error_frame(0x200, bytes([0, 0, 0, 0, 0, 0, tx, rx]))
    assert (frame.tx_errors, frame.rx_errors, frame.state) == (tx, rx, state)


def test_protocol_transceiver_arbitration_and_ack_in_words() -> None:
    frame = decode_error_frame(0x008 | 0x010 | 0x002 | 0x020,
                               bytes([12, 0, 0x04 | 0x80, 0x08, 0x40, 0, 0, 0]))
    assert frame.classes == ("lost_arbitration", "protocol", "transceiver", "no_ack")
    text = frame.text()
    for words in ("lost arbitration at bit 12", "bit stuffing error", "error on transmission",
                  "at CRC sequence", "transceiver: CANL no wire", "no ACK"):
        assert words in text, (words, text)
    assert frame.state is None
    assert decode_error_frame(0x001 | 0x080, b"").classes == ("tx_timeout", "bus_error")


def test_the_watch_counts_per_class_and_says_bus_off_and_passive(caplog) -> None:
    watch = ErrorFrameWatch()
    caplog.set_level(logging.WARNING)
    for _ in range(50):
        watch.observe(0x020, bytes(8))  # no ACK: a lone node
    for msg in error_frames(bus_off=False, on=True):
        watch.observe(msg.arbitration_id, msg.data)
    assert "error passive" in watch.warning() and not watch.problem()
    for msg in error_frames(bus_off=True, on=True):
        watch.observe(msg.arbitration_id, msg.data)
    assert "bus-off" in watch.problem() and not watch.warning()
    figures = watch.figures()
    assert figures["error_frames_no_ack"] == 50 and figures["error_frames_bus_off"] == 1
    assert figures["error_frames_controller"] == 4 and figures["can_tx_error_counter"] == 255
    assert figures["can_controller_state"] == ce.BUS_OFF
    assert set(error_frame_keys()) <= set(figures)
    for msg in error_frames(bus_off=True, on=False):
        watch.observe(msg.arbitration_id, msg.data)
    assert not watch.problem() and not watch.warning()
    assert watch.figures()["can_controller_state"] == ce.ERROR_ACTIVE
    # one line per class within the second the burst took
    lines = [r.getMessage() for r in caplog.records if "CAN error frame" in r.getMessage()]
    assert sum("(no_ack," in line for line in lines) == 1, lines
    assert sum("(bus_off," in line for line in lines) == 1, lines


def test_the_simulated_frames_are_socketcans() -> None:
    """What python-can's socketcan delivers for an error frame: is_error_frame, the class
    mask as a standard identifier, 8 data bytes."""
    msg = error_frame(0x040)
    assert msg.is_error_frame and not msg.is_extended_id and msg.dlc == 8
    assert [decode_error_frame(m.arbitration_id, m.data).state
            for m in error_frames(bus_off=True, on=True)] == [
        ce.ERROR_WARNING, ce.ERROR_PASSIVE, ce.BUS_OFF]
    assert isinstance(msg, can.Message)


def test_bus_off_ends_when_frames_keep_coming() -> None:
    """A driver that reports no restart: frames received again show the controller works
    (a bus-off controller receives nothing); one straggler does not."""
    from ssi_bridge.client.error_frames import RECOVERY_FRAMES

    watch = ErrorFrameWatch()
    watch.observe(0x040, bytes(8))
    watch.heard(0x181)
    assert watch.bus_off
    for _ in range(RECOVERY_FRAMES):
        watch.heard(0x181)
    assert not watch.bus_off and not watch.problem()
