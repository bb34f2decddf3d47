"""The preset of object 0x6810 is added to the encoder value, as 000 says.

000, chapter 4, "Object 6810hex - Preset Values for Multi-Sensor Devices": "Object 6810hex
(corresponds to object 6010hex in accordance with CiA DS406) is used for zero point
adaption. The content of this object is added to the value of the SSI encoder. The resulting
value is stored in object 6820hex." The module underneath subtracts REG_OFFSET (000 ch. 1
"Offset function": REG_SSI_POS = SSI encoder - REG_OFFSET), so the gateway keeps
REG_OFFSET = -(0x6810) and both sentences hold (docs/canopen.md "Preset: object 0x6810").
The preset goes over the wire through canopen's own SDO client (``RemoteNode.sdo``).
"""

from __future__ import annotations

import struct

from ssi_bridge.protocol.registers import Reg


def test_a_preset_written_through_0x6810_is_added_to_the_encoder_value(station) -> None:
    sdo, module = station.node.sdo, station.gateway.modules[0]
    station.sync()
    assert sdo[0x6820][1].raw == 1000          # the encoder value of slot 1, no preset
    sdo[0x6810][1].raw = 250                   # SDO download of Integer32 250
    station.sync()
    assert sdo[0x6820][1].raw == 1000 + 250, "000: the preset 'is added' to the encoder value"
    assert sdo[0x6810][1].raw == 250           # reads back as written
    assert module.read_register(Reg.REG_OFFSET) == -250 & 0xFFFFFFFF  # 000 ch. 1 subtracts
    assert sdo[0x6820][2].raw == 2000          # slot 2 untouched


def test_a_negative_preset_and_the_raw_sdo_bytes(station) -> None:
    sdo = station.node.sdo
    sdo.download(0x6810, 1, struct.pack("<i", -1500))  # the Integer32 bytes on the wire
    station.sync()
    assert sdo[0x6820][1].raw == 1000 - 1500 == -500
    assert struct.unpack("<i", sdo.upload(0x6810, 1))[0] == -1500
    sdo[0x6810][1].raw = 0                     # 0: no zero point shift
    station.sync()
    assert sdo[0x6820][1].raw == 1000
    sdo[0x6810][1].raw = -0x80000000           # the Integer32 extreme reads back unchanged
    assert sdo[0x6810][1].raw == -0x80000000
