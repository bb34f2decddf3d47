"""canopen's ``ObjectDictionary`` of an XN-GW-CANOPEN station, built from the protocol table.

Both ends of the wire need it: the master's ``RemoteNode`` (typed SDO access, PDO maps) and
the simulated gateway's ``LocalNode``. The objects themselves (indices, types, access) are
:mod:`ssi_bridge.protocol.dictionary`; this module only turns them into canopen's classes and
exports the EDS.
"""

from __future__ import annotations

from canopen import objectdictionary as od
from canopen.objectdictionary import eds

from ssi_bridge.base.canopen_compat import set_eds_default
from ssi_bridge.protocol.dictionary import (
    DEVICE_NAME, DEVICE_TYPE, ENCODER_OBJECTS, ERROR_HISTORY, IDENTITY_COMMENT, MAP_ENTRIES,
    MAX_SLOTS, N_PDOS, PROCESS_INPUT, PROCESS_OUTPUT, PRODUCT_CODE, REVISION, RPDO_COM,
    RPDO_MAP, SERIAL, SIM_ACTIVE, SIM_COMMAND, SIM_DURATION, SIM_EPOCH, SIM_RATE, SIMULATION,
    TPDO_COM, TPDO_MAP, TRANS_EVENT, VENDOR_ID, PDO_INVALID, rpdo_cob_base, tpdo_cob_base,
)
from ssi_bridge.protocol.dictionary import DataType as dt
from ssi_bridge.protocol.settings import CIA_BITRATES


def _var(name: str, index: int, sub: int, data_type: int, access: str, default: object = None,
         *, pdo: bool = False, cob_base: int | None = None, node_id: int = 0) -> od.ODVariable:
    var = od.ODVariable(name, index, sub)
    var.data_type = int(data_type)
    var.access_type = access
    var.pdo_mappable = pdo
    if cob_base is not None:
        var.default = cob_base + node_id
        set_eds_default(var, f"$NODEID+0x{cob_base:X}")
        var.relative = True
    else:
        var.default = default  # type: ignore[assignment]  # canopen: int; REAL32 and strings too
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


#: what each simulation-only object does; in the EDS's [Comments] (CiA 306 has no per-object
#: description key: a ``Description=`` line in an object section fails lely's dcfchk)
SIMULATION_OBJECTS: tuple[tuple[int, str, int, str, str], ...] = (
    (SIM_RATE, "SIM fault rate", dt.REAL32, "rw",
     "rate 0-1 of the next BIT_NOISE / CAN_FRAME_LOSS command"),
    (SIM_DURATION, "SIM fault duration ms", dt.UNSIGNED32, "rw",
     "duration of the next command in ms, 0 = until CLEAR_ALL; the station times it"),
    (SIM_COMMAND, "SIM fault command", dt.UNSIGNED16, "rw",
     "write kind (bits 0-7, InjectFault numbers, 0 = CLEAR_ALL) | slot << 8 (0 = bus faults) "
     "to inject"),
    (SIM_ACTIVE, "SIM faults active", dt.UNSIGNED32, "ro",
     "bit k set while a fault of kind k is in force"),
    (SIM_EPOCH, "SIM motion epoch us", dt.UNSIGNED64, "ro",
     "wire time (CLOCK_REALTIME, microseconds since 1970) at which the simulated encoders' "
     "motion time is 0"),
)


def _simulation_objects(d: od.ObjectDictionary) -> None:
    """0x4000-0x4004: fault injection and motion epoch of the simulated station (simulation
    only)."""
    for index, name, data_type, access, _text in SIMULATION_OBJECTS:
        var = _var(name, index, 0, data_type, access, 0.0 if data_type == dt.REAL32 else 0)
        if data_type == dt.REAL32:
            # CiA 306 writes a REAL32 value as an integer (its IEEE 754 bits): 0.0 is "0",
            # which canopen's import also reads as 0.0
            set_eds_default(var, "0")
        d.add_object(var)


def build_dictionary(node_id: int, slots: int) -> od.ObjectDictionary:
    """Return the dictionary of a station with ``slots`` XN-1SSI modules at ``node_id``.

    :raises ValueError: ``slots`` outside 1-MAX_SLOTS
    """
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
    # canopen annotates these counts bool
    d.device_information.nr_of_RXPDO = N_PDOS  # type: ignore[assignment]
    d.device_information.nr_of_TXPDO = N_PDOS  # type: ignore[assignment]
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
    sim = "".join(f"0x{index:04X} {name} ({access}): {text}\n"
                  for index, name, _t, access, text in SIMULATION_OBJECTS)
    d.comments = ("Objects 0x4000-0x4004 exist only in the simulated station (ssi_bridge): "
                  "fault injection and the motion epoch.\nA real XN-GW-CANOPEN aborts access to "
                  "them (0x06020000, object does not exist).\n" + sim + IDENTITY_COMMENT +
                  "\n0x6800-0x6FFF: the CiA 406 encoder profile as the gateway's second logical "
                  "device (CiA 406 index + 0x800; 0x6FFF = 0x000A0196).")
    stamp = {"CreationDate": "01-01-2025", "CreationTime": "12:00AM",
             "ModificationDate": "01-01-2025", "ModificationTime": "12:00AM",
             "EdsVersion": "4.2", "Description": f"XN-GW-CANOPEN with {slots} XN-1SSI"}
    with open(path, "w", encoding="ascii") as fh:
        eds.export_eds(d, fh, file_info=stamp)
