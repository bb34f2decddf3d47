"""The XN-GW-CANOPEN object dictionary as both ends know it (000 chapter 4, Table 16): pure data.

Indices, COB-IDs, data types and access of every object, no canopen: the master and the
simulated gateway each build canopen's ``ObjectDictionary`` from this table with
:func:`ssi_bridge.base.od.build_dictionary`. ``config/xn_gw_canopen.eds`` is the dictionary
of a full 8-slot station, exported by :func:`ssi_bridge.base.od.write_eds` and compared
object by object with a live gateway in the tests.

Layout (see ``docs/canopen.md``):

* communication objects 0x1000-0x1018 (CiA 301);
* RPDO1-12 / TPDO1-12 communication and mapping records. PDO1-8 carry the raw process
  images of slots 1-8 (objects 0x2000/0x2100), PDO9-12 are the encoder default PDOs of
  000 Table 15. All are invalid by default (bit 31 of the COB-ID set);
* 0x2000 / 0x2100: manufacturer ARRAYs of UNSIGNED64, the 8-byte process input / output
  image of each slot, image byte k in bits 8k..8k+7 (the CAN payload is the image in order);
* the encoder objects of Table 16 as ARRAYs (sub 0 = number of slots), the data types,
  access and PDO mapping of description Tables 17-49;
* 0x4000-0x4004: simulation only, fault injection into the simulated station and its motion
  epoch (not in the manual; a real gateway has no such objects).
"""

from __future__ import annotations

from dataclasses import dataclass

from enum import IntEnum


class DataType(IntEnum):
    """CiA 301 data type codes (Table 44 of CiA 301 v4.2; canopen's ``datatypes`` uses them)."""

    BOOLEAN = 0x01
    INTEGER8 = 0x02
    INTEGER16 = 0x03
    INTEGER32 = 0x04
    UNSIGNED8 = 0x05
    UNSIGNED16 = 0x06
    UNSIGNED32 = 0x07
    REAL32 = 0x08
    VISIBLE_STRING = 0x09
    INTEGER64 = 0x15
    UNSIGNED64 = 0x1B


dt = DataType

#: CiA 301 default COB-ID of SYNC (no node id: one producer per bus)
SYNC_COB_ID = 0x080
#: number of XN-1SSI modules a station may hold
MAX_SLOTS = 8

#: CiA 301 NMT module control (COB-ID 0x000, 2 bytes: command specifier, node id; 0 = all)
NMT_COB_ID = 0x000
NMT_START = 0x01
NMT_STOP = 0x02
NMT_ENTER_PRE_OPERATIONAL = 0x80
NMT_RESET_NODE = 0x81
NMT_RESET_COMMUNICATION = 0x82
#: CiA 301 error control (heartbeat / boot-up) COB-ID base: 0x700 + node id
NMT_ERROR_CONTROL = 0x700
#: CiA 301 heartbeat states (byte 0, bits 6..0): the only values a heartbeat may carry
NMT_STATE_BOOTUP = 0x00
NMT_STATE_STOPPED = 0x04
NMT_STATE_OPERATIONAL = 0x05
NMT_STATE_PRE_OPERATIONAL = 0x7F
NMT_STATES = {NMT_STATE_BOOTUP: "BOOT-UP", NMT_STATE_STOPPED: "STOPPED",
              NMT_STATE_OPERATIONAL: "OPERATIONAL",
              NMT_STATE_PRE_OPERATIONAL: "PRE-OPERATIONAL"}
#: 0x1000 device type: CiA 401 generic I/O (the gateway's first device profile)
DEVICE_TYPE = 0x0000_0191
#: 0x6FFF device type of the second profile: DS406, multi-sensor encoder interface (Table 49)
ENCODER_DEVICE_TYPE = 0x000A_0196
DEVICE_NAME = "XN-GW-CANOPEN"
#: 0x1018 identity. 000 gives no Vendor-ID, product code or serial number: those three are
#: simulation values (named so in the dictionary and the EDS), not Eaton's assignments. The
#: revision number is the one figure the manual gives: "The support of XN-1SSI modules has
#: been implemented from firmware version V3.00 of XN-GW-CANOPEN" (000 ch. 4), as CiA 301
#: major.minor in the upper / lower 16 bits.
VENDOR_ID = 0x0000_0000
PRODUCT_CODE = 0x0000_6811
SERIAL = 0x0000_0001
REVISION = 0x0003_0000
SIMULATION = " (simulation value)"
IDENTITY_COMMENT = (
    "0x1018: Vendor-ID, Product code and Serial number are simulation values: the XN-1SSI "
    "manual does not give them.\nRevision number 0x00030000 = firmware V3.00, from which "
    "XN-GW-CANOPEN supports XN-1SSI modules (manual ch. 4).")
#: CiA 301 PDO COB-ID bit 31: PDO does not exist / is not valid
PDO_INVALID = 0x8000_0000
#: CiA 301 PDO COB-ID bit 30: no RTR allowed on this PDO
PDO_NO_RTR = 0x4000_0000
#: transmission type: event-driven, manufacturer specific (000 Table 15: "normally 255")
TRANS_EVENT = 255
#: highest PDO number of the station (PDO1-8 images, PDO9-12 encoder defaults)
N_PDOS = 12
#: max number of mapping entries per PDO
MAP_ENTRIES = 8
#: entries kept in 0x1003 pre-defined error field
ERROR_HISTORY = 8

TPDO_COM, TPDO_MAP, RPDO_COM, RPDO_MAP = 0x1800, 0x1A00, 0x1400, 0x1600
#: simulation-only objects (manufacturer area; not on a real XN-GW-CANOPEN): fault injection
#: rate (REAL32 0-1), duration (ms, 0 = until cleared), command (kind | slot << 8) and the
#: kinds in force (bit mask); served by sim/gateway/simulation.py
SIM_RATE, SIM_DURATION, SIM_COMMAND, SIM_ACTIVE = 0x4000, 0x4001, 0x4002, 0x4003
#: simulation-only: the station's motion epoch, the wire time (CLOCK_REALTIME) at which every
#: simulated encoder's motion time is 0, in whole microseconds (UNSIGNED64, read-only)
SIM_EPOCH = 0x4004
PROCESS_INPUT, PROCESS_OUTPUT = 0x2000, 0x2100


_GROUP_OFFSET = (0x00, 0x40, 0x60)


def tpdo_cob_base(pdo: int) -> int:
    """Return the TPDO COB-ID without node id for PDO ``pdo`` (1-12).

    PDO1-4 follow the CiA 301 pre-defined connection set (0x180 .. 0x480), PDO5-8 the XI/ON
    pattern +0x40 (0x1C0 .. 0x4C0), PDO9-12 000 Table 15 (0x1E0 .. 0x4E0).
    """
    group, k = divmod(pdo - 1, 4)
    return 0x180 + 0x100 * k + _GROUP_OFFSET[group]


def rpdo_cob_base(pdo: int) -> int:
    """Return the RPDO COB-ID without node id (PDO9-12: 0x260 .. 0x560, 000 Table 15).

    :param pdo: the PDO's number (1-12), as :func:`tpdo_cob_base`
    """
    return tpdo_cob_base(pdo) + 0x80


@dataclass(frozen=True)
class EncoderObject:
    """One Table 16 object: index, name, CANopen data type, access, PDO-mappable, ARRAY?

    ``profile`` is the CiA 406 (DS406) object it is in the gateway's second logical device
    (index - 0x800, 000 "Overview of Encoders Device Profile Range"; 0 for the manufacturer
    objects 0x58xx), and then ``name`` is CiA 406's name of that object.
    """

    index: int
    name: str
    data_type: int
    access: str
    pdo: bool
    array: bool = True
    default: int = 0
    profile: int = 0


#: offset of the gateway's second logical device (CiA 406) from the profile's own indices
ENCODER_PROFILE_OFFSET = 0x800


def _p(index: int, name: str, data_type: int, access: str, pdo: bool, array: bool = True,
       default: int = 0) -> EncoderObject:
    """A CiA 406 object of the second logical device: index 0x68xx-0x6FFF = CiA 406's + 0x800."""
    return EncoderObject(index, name, data_type, access, pdo, array, default,
                         profile=index - ENCODER_PROFILE_OFFSET)


#: Table 16 with the description tables 17-49 (types/access/mapping); "no function" objects
#: keep the type DS406 gives them. 0x5803/0x5805 are "rwr" (rw, mappable for reading). The
#: 0x58xx names are 000's (manufacturer objects); the 0x68xx-0x6FFF names are CiA 406's (for
#: 0x6810/0x6820 as 000 Table 16 spells them; 0x6FFF says which "Device type" it is, so that
#: a lookup by name still finds 0x1000).
ENCODER_OBJECTS: tuple[EncoderObject, ...] = (
    EncoderObject(0x5800, "Encoder Basic Mode", dt.UNSIGNED8, "rw", False),
    EncoderObject(0x5801, "Encoder Config", dt.UNSIGNED32, "rw", False),
    EncoderObject(0x5802, "Encoder Status", dt.UNSIGNED8, "ro", True),
    EncoderObject(0x5803, "Encoder Flags", dt.UNSIGNED8, "rwr", True),
    EncoderObject(0x5804, "Encoder Diag", dt.UNSIGNED8, "ro", False),
    EncoderObject(0x5805, "SSI Native Status", dt.UNSIGNED16, "rwr", True),
    EncoderObject(0x5806, "SSI Optional Encoder Status", dt.UNSIGNED8, "ro", True),
    EncoderObject(0x5808, "Encoder Control", dt.UNSIGNED8, "rw", False),
    EncoderObject(0x5810, "Counter Load Prepare Value", dt.INTEGER32, "rw", False),
    EncoderObject(0x5811, "Counter Pulse Width", dt.UNSIGNED16, "rw", False),
    EncoderObject(0x5820, "Measuring Integration Time", dt.UNSIGNED16, "rw", False),
    EncoderObject(0x5821, "Measuring Low Limit", dt.INTEGER32, "rw", False),
    EncoderObject(0x5822, "Measuring High Limit", dt.INTEGER32, "rw", False),
    EncoderObject(0x5823, "Measuring Units per Revolution", dt.UNSIGNED32, "rw", False),
    EncoderObject(0x5840, "SSI Diag Mapping", dt.UNSIGNED32, "rw", False),
    _p(0x6800, "Operating parameters", dt.UNSIGNED16, "rw", False, array=False),
    _p(0x6810, "Preset value for multi-sensor devices", dt.INTEGER32, "rw", True),
    _p(0x6820, "Position value for multi-sensor devices", dt.INTEGER32, "ro", True),
    _p(0x6B00, "Cam state register", dt.UNSIGNED8, "ro", True),
    _p(0x6B01, "Cam enable register", dt.UNSIGNED8, "rw", False),
    _p(0x6B02, "Cam polarity register", dt.UNSIGNED8, "rw", False),
    _p(0x6B10, "Cam1 low limit", dt.INTEGER32, "rw", False),
    _p(0x6B20, "Cam1 high limit", dt.INTEGER32, "rw", False),
    _p(0x6B30, "Cam1 hysteresis", dt.UNSIGNED16, "rw", False),
    _p(0x6C00, "Area state register", dt.UNSIGNED8, "ro", True),
    _p(0x6C01, "Work area low limit", dt.INTEGER32, "rw", False),
    _p(0x6C02, "Work area high limit", dt.INTEGER32, "rw", False),
    _p(0x6D00, "Operating status", dt.UNSIGNED16, "ro", False, array=False),
    _p(0x6D01, "Singleturn resolution", dt.UNSIGNED32, "ro", False, array=False),
    _p(0x6D02, "Number of distinguishable revolutions", dt.UNSIGNED16, "ro", False,
       array=False),
    _p(0x6FFF, "Device type (second logical device)", dt.UNSIGNED32, "const", False, array=False,
       default=ENCODER_DEVICE_TYPE),
)
