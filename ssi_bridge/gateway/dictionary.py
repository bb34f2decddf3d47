"""The object dictionary of the simulated XN-GW-CANOPEN station (000 chapter 4, Table 16).

Built in code so the slot count (1-8 XN-1SSI modules) is a parameter; ``config/
xn_gw_canopen.eds`` is this dictionary for a full 8-slot station, exported by
:func:`write_eds` and compared object by object with a live gateway in the tests.

Layout (see ``docs/canopen.md``):

* communication objects 0x1000-0x1018 (CiA 301);
* RPDO1-12 / TPDO1-12 communication and mapping records. PDO1-8 carry the raw process
  images of slots 1-8 (objects 0x2000/0x2100), PDO9-12 are the encoder default PDOs of
  000 Table 15. All are invalid by default (bit 31 of the COB-ID set);
* 0x2000 / 0x2100: manufacturer ARRAYs of UNSIGNED64, the 8-byte process input / output
  image of each slot, image byte k in bits 8k..8k+7 (the CAN payload is the image in order);
* the encoder objects of Table 16 as ARRAYs (sub 0 = number of slots), the data types,
  access and PDO mapping of description Tables 17-49;
* 0x4000-0x4003: simulation only, fault injection into the simulated station (not in the
  manual; a real gateway has no such objects).
"""

from __future__ import annotations

from dataclasses import dataclass

from canopen import objectdictionary as od
from canopen.objectdictionary import datatypes as dt
from canopen.objectdictionary import eds

from ssi_bridge.gateway.bus import CIA_BITRATES

#: number of XN-1SSI modules a station may hold
MAX_SLOTS = 8
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
#: kinds in force (bit mask); served by gateway/simulation.py
SIM_RATE, SIM_DURATION, SIM_COMMAND, SIM_ACTIVE = 0x4000, 0x4001, 0x4002, 0x4003
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
    """Return the RPDO COB-ID without node id (PDO9-12: 0x260 .. 0x560, 000 Table 15)."""
    return tpdo_cob_base(pdo) + 0x80


@dataclass(frozen=True)
class EncoderObject:
    """One Table 16 object: index, name, CANopen data type, access, PDO-mappable, ARRAY?"""

    index: int
    name: str
    data_type: int
    access: str
    pdo: bool
    array: bool = True
    default: int = 0


#: Table 16 with the description tables 17-49 (types/access/mapping); "no function" objects
#: keep the type DS406 gives them. 0x5803/0x5805 are "rwr" (rw, mappable for reading).
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
    EncoderObject(0x6800, "Operating parameters", dt.UNSIGNED16, "rw", False, array=False),
    EncoderObject(0x6810, "Preset value for multi-sensor devices", dt.INTEGER32, "rw", True),
    EncoderObject(0x6820, "Position value for multi-sensor devices", dt.INTEGER32, "ro", True),
    EncoderObject(0x6B00, "Cam state register", dt.UNSIGNED8, "ro", True),
    EncoderObject(0x6B01, "Cam enable register", dt.UNSIGNED8, "rw", False),
    EncoderObject(0x6B02, "Cam polarity register", dt.UNSIGNED8, "rw", False),
    EncoderObject(0x6B10, "Cam 1 low limit", dt.INTEGER32, "rw", False),
    EncoderObject(0x6B20, "Cam 1 high limit", dt.INTEGER32, "rw", False),
    EncoderObject(0x6B30, "Cam 1 hysteresis", dt.UNSIGNED16, "rw", False),
    EncoderObject(0x6C00, "Area State Register", dt.UNSIGNED8, "ro", True),
    EncoderObject(0x6C01, "Work Area Low Limit", dt.INTEGER32, "rw", False),
    EncoderObject(0x6C02, "Work Area High Limit", dt.INTEGER32, "rw", False),
    EncoderObject(0x6D00, "Operating Status", dt.UNSIGNED16, "ro", False, array=False),
    EncoderObject(0x6D01, "SingleTurn Resolution", dt.UNSIGNED32, "ro", False, array=False),
    EncoderObject(0x6D02, "Number of distinguishable revolutions", dt.UNSIGNED16, "ro",
                  False, array=False),
    EncoderObject(0x6FFF, "Device Type", dt.UNSIGNED32, "const", False, array=False,
                  default=ENCODER_DEVICE_TYPE),
)


def _var(name: str, index: int, sub: int, data_type: int, access: str, default: object = None,
         *, pdo: bool = False, cob_base: int | None = None, node_id: int = 0) -> od.ODVariable:
    var = od.ODVariable(name, index, sub)
    var.data_type = data_type
    var.access_type = access
    var.pdo_mappable = pdo
    if cob_base is not None:
        var.default = cob_base + node_id
        var.default_raw = f"$NODEID+0x{cob_base:X}"
        var.relative = True
    else:
        var.default = default
    return var


def _array(index: int, name: str, slots: int, data_type: int, access: str, pdo: bool,
           default: int = 0) -> od.ODArray:
    arr = od.ODArray(name, index)
    arr.add_member(_var("Number of entries", index, 0, dt.UNSIGNED8, "ro", slots))
    for slot in range(1, slots + 1):
        arr.add_member(_var(f"{name} slot {slot}", index, slot, data_type, access, default,
                            pdo=pdo))
    return arr


def _record(index: int, name: str, members: list[od.ODVariable]) -> od.ODRecord:
    rec = od.ODRecord(name, index)
    for member in members:
        rec.add_member(member)
    return rec


def _pdo_objects(d: od.ObjectDictionary, node_id: int) -> None:
    for pdo in range(1, N_PDOS + 1):
        n = pdo - 1
        for com, mp, kind, base in ((RPDO_COM, RPDO_MAP, "RPDO", rpdo_cob_base(pdo)),
                                    (TPDO_COM, TPDO_MAP, "TPDO", tpdo_cob_base(pdo))):
            members = [
                _var("Highest sub-index supported", com + n, 0, dt.UNSIGNED8, "const",
                     2 if kind == "RPDO" else 6),
                _var("COB-ID", com + n, 1, dt.UNSIGNED32, "rw",
                     cob_base=base | PDO_INVALID, node_id=node_id),
                _var("Transmission type", com + n, 2, dt.UNSIGNED8, "rw", TRANS_EVENT),
            ]
            if kind == "TPDO":
                members += [
                    _var("Inhibit time", com + n, 3, dt.UNSIGNED16, "rw", 0),
                    _var("Event timer", com + n, 5, dt.UNSIGNED16, "rw", 0),
                    _var("SYNC start value", com + n, 6, dt.UNSIGNED8, "rw", 0)]
            d.add_object(_record(com + n, f"{kind}{pdo} communication parameter", members))
            mapping = [_var("Number of mapped objects", mp + n, 0, dt.UNSIGNED8, "rw", 0)]
            mapping += [_var(f"Mapped object {k}", mp + n, k, dt.UNSIGNED32, "rw", 0)
                        for k in range(1, MAP_ENTRIES + 1)]
            d.add_object(_record(mp + n, f"{kind}{pdo} mapping parameter", mapping))


def _simulation_objects(d: od.ObjectDictionary) -> None:
    """0x4000-0x4003: fault injection of the simulated station (simulation only)."""
    for index, name, data_type, access, default, text in (
            (SIM_RATE, "SIM fault rate", dt.REAL32, "rw", 0.0,
             "rate 0-1 of the next BIT_NOISE / CAN_FRAME_LOSS command"),
            (SIM_DURATION, "SIM fault duration ms", dt.UNSIGNED32, "rw", 0,
             "duration of the next command in ms, 0 = until CLEAR_ALL; the station times it"),
            (SIM_COMMAND, "SIM fault command", dt.UNSIGNED16, "rw", 0,
             "write kind (bits 0-7, InjectFault numbers, 0 = CLEAR_ALL) | slot << 8 "
             "(0 = bus faults) to inject"),
            (SIM_ACTIVE, "SIM faults active", dt.UNSIGNED32, "ro", 0,
             "bit k set while a fault of kind k is in force")):
        var = _var(name, index, 0, data_type, access, default)
        var.description = f"SIMULATION ONLY (no such object on a real gateway): {text}"
        d.add_object(var)


def build_dictionary(node_id: int, slots: int) -> od.ObjectDictionary:
    """Return the dictionary of a station with ``slots`` XN-1SSI modules at ``node_id``."""
    if not 1 <= slots <= MAX_SLOTS:
        raise ValueError(f"a station holds 1-{MAX_SLOTS} XN-1SSI modules, not {slots}")
    d = od.ObjectDictionary()
    d.node_id = node_id
    d.device_information.product_name = DEVICE_NAME
    d.device_information.vendor_name = "Eaton (simulated)"
    d.device_information.vendor_number = VENDOR_ID
    d.device_information.product_number = PRODUCT_CODE
    d.device_information.revision_number = REVISION
    d.device_information.allowed_baudrates = set(CIA_BITRATES)
    d.device_information.nr_of_RXPDO = N_PDOS
    d.device_information.nr_of_TXPDO = N_PDOS
    d.add_object(_var("Device type", 0x1000, 0, dt.UNSIGNED32, "ro", DEVICE_TYPE))
    d.add_object(_var("Error register", 0x1001, 0, dt.UNSIGNED8, "ro", 0))
    errors = od.ODArray("Pre-defined error field", 0x1003)
    errors.add_member(_var("Number of errors", 0x1003, 0, dt.UNSIGNED8, "rw", 0))
    for k in range(1, ERROR_HISTORY + 1):
        errors.add_member(_var(f"Standard error field {k}", 0x1003, k, dt.UNSIGNED32, "ro", 0))
    d.add_object(errors)
    d.add_object(_var("COB-ID SYNC", 0x1005, 0, dt.UNSIGNED32, "rw", 0x80))
    d.add_object(_var("Manufacturer device name", 0x1008, 0, dt.VISIBLE_STRING, "const",
                      DEVICE_NAME))
    d.add_object(_var("COB-ID EMCY", 0x1014, 0, dt.UNSIGNED32, "ro", cob_base=0x80,
                      node_id=node_id))
    d.add_object(_var("Producer heartbeat time", 0x1017, 0, dt.UNSIGNED16, "rw", 0))
    d.add_object(_record(0x1018, "Identity object", [
        _var("Highest sub-index supported", 0x1018, 0, dt.UNSIGNED8, "const", 4),
        _var("Vendor-ID" + SIMULATION, 0x1018, 1, dt.UNSIGNED32, "ro", VENDOR_ID),
        _var("Product code" + SIMULATION, 0x1018, 2, dt.UNSIGNED32, "ro", PRODUCT_CODE),
        _var("Revision number", 0x1018, 3, dt.UNSIGNED32, "ro", REVISION),
        _var("Serial number" + SIMULATION, 0x1018, 4, dt.UNSIGNED32, "ro", SERIAL)]))
    _pdo_objects(d, node_id)
    d.add_object(_array(PROCESS_INPUT, "Process input image", slots, dt.UNSIGNED64, "ro",
                        True))
    d.add_object(_array(PROCESS_OUTPUT, "Process output image", slots, dt.UNSIGNED64, "rw",
                        True))
    _simulation_objects(d)
    for obj in ENCODER_OBJECTS:
        if obj.array:
            d.add_object(_array(obj.index, obj.name, slots, obj.data_type, obj.access, obj.pdo,
                                obj.default))
        else:
            d.add_object(_var(obj.name, obj.index, 0, obj.data_type, obj.access, obj.default,
                              pdo=obj.pdo))
    return d


def write_eds(path: str, slots: int = MAX_SLOTS) -> None:
    """Export the dictionary of a ``slots``-module station as an EDS file to ``path``."""
    d = build_dictionary(1, slots)
    d.comments = ("Objects 0x4000-0x4003 exist only in the simulated station (ssi_bridge): "
                  "fault injection.\nA real XN-GW-CANOPEN aborts access to them "
                  "(0x06020000, object does not exist).\n" + IDENTITY_COMMENT)
    stamp = {"CreationDate": "01-01-2025", "CreationTime": "12:00AM",
             "ModificationDate": "01-01-2025", "ModificationTime": "12:00AM",
             "EdsVersion": "4.2", "Description": f"XN-GW-CANOPEN with {slots} XN-1SSI"}
    with open(path, "w", encoding="ascii") as fh:
        eds.export_eds(d, fh, file_info=stamp)
