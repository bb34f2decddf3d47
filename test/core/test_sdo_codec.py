"""The typed codec of ~/sdo_read / ~/sdo_write (core/sdo_access.py): CiA 301 little-endian
values of each basic data type, and the refusals a request gets before anything is sent."""

from __future__ import annotations

import struct

import pytest

from ssi_bridge.core.sdo_access import decode, encode, type_named, value_kind
from ssi_bridge.exceptions import ConfigError
from ssi_bridge.protocol.dictionary import DataType as dt


@pytest.mark.parametrize("data_type, value, data", [
    (dt.INTEGER8, -2, b"\xfe"),
    (dt.INTEGER16, -300, struct.pack("<h", -300)),
    (dt.INTEGER32, -123456, struct.pack("<i", -123456)),
    (dt.UNSIGNED8, 255, b"\xff"),
    (dt.UNSIGNED16, 0xBEEF, b"\xef\xbe"),
    (dt.UNSIGNED32, 0x000A0196, b"\x96\x01\x0a\x00"),
    (dt.REAL32, 0.25, struct.pack("<f", 0.25)),
    (dt.VISIBLE_STRING, "XN-GW-CANOPEN", b"XN-GW-CANOPEN"),
])
def test_values_round_trip_little_endian(data_type, value, data) -> None:
    assert encode(data_type, value) == data
    assert decode(data_type, data) == value


@pytest.mark.parametrize("data_type, value, words", [
    (dt.INTEGER8, 128, "-128..127"),
    (dt.UNSIGNED16, -1, "0..65535"),
    (dt.UNSIGNED32, 1 << 32, "UNSIGNED32"),
    (dt.REAL32, float("nan"), "finite"),
    (dt.REAL32, 1e39, "finite"),
    (dt.VISIBLE_STRING, "\u20ac", "latin-1"),
])
def test_values_outside_the_type_are_refused(data_type, value, words) -> None:
    with pytest.raises(ConfigError, match=words):
        encode(data_type, value)


def test_a_length_that_does_not_fit_the_type_is_refused() -> None:
    with pytest.raises(ConfigError, match="4 byte"):
        decode(dt.UNSIGNED16, b"\x00\x00\x00\x00")


def test_type_names_and_fields() -> None:
    assert type_named("") is None
    assert type_named(" integer32 ") is dt.INTEGER32
    with pytest.raises(ConfigError, match="not one of"):
        type_named("FLOAT")
    assert [value_kind(t) for t in (dt.INTEGER16, dt.UNSIGNED8, dt.REAL32, dt.VISIBLE_STRING,
                                    dt.BOOLEAN)] == ["signed", "unsigned", "float", "string",
                                                     "unsigned"]
