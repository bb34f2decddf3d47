"""Typed access to any object of a station (``~/sdo_read`` / ``~/sdo_write``), ROS-free.

A CANopen user reads and writes objects by index, subindex and data type (CiA 301 §7.4.7 data
types; ros2_canopen's ``sdo_read``/``sdo_write``). The transfer itself is the master's SDO
client (raw bytes, so a station's own abort such as 0x06020000 "object does not exist"
reaches the caller for an object no dictionary knows); this module picks the station, the
type (the EDS's by default, or the one named), encodes and decodes, and keeps the node's
truths in step:

* 0x5801 (Encoder Config = REG_PARA1, 000 Table 17) of a configured joint's slot is written
  through :meth:`Bridge.change_para1`, the one REG_PARA1 path of ``~/write_register`` and
  ``<joint>.para1``: checked against the module's rules, the parameter, the scale and the
  velocity estimate follow;
* 0x6810 (Preset value = REG_OFFSET, 000 Table 39) moves the zero point: the joint's velocity
  estimate is held across the write, as ``~/set_preset`` does;
* the CAM objects 0x6B01/0x6B02/0x6B10/0x6B20 (000 Tables 43-48) are read back into the
  joint's frame watch at once, so the CAM state the node computes follows the write;
* objects the master configures and owns (SYNC, heartbeat, PDO parameters, the process
  output image of the register handshake, the simulated station's fault objects) are
  refused for writing, naming the service to use instead: a write there would stop the cycle
  or bypass the node's own state.

A listen-only node (``bus.listen_only``, ``replay.can_log``) has no SDO client: its client
refuses the transfer, as it refuses the register handshake.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable

from ssi_bridge.base.timebase import wire_now
from ssi_bridge.core.bridge import ENCODER_CONFIG, Bridge
from ssi_bridge.core.frame_watch import CAM_ENABLE, CAM_HIGH, CAM_LOW, CAM_POLARITY, read_cam
from ssi_bridge.core.joint import Joint
from ssi_bridge.core.ports import DictionaryEntry, RawSdo, StationClient
from ssi_bridge.exceptions import BusError, ConfigError
from ssi_bridge.protocol.dictionary import (
    PROCESS_OUTPUT, RPDO_COM, SIM_ACTIVE, SIM_RATE, DataType,
)

#: object 0x6810 Preset value for multi-sensor devices = REG_OFFSET (000 Table 39)
PRESET = 0x6810
CAM_OBJECTS = (CAM_ENABLE, CAM_POLARITY, CAM_LOW, CAM_HIGH)

#: little-endian layouts of the fixed-size types (CiA 301: every value is little endian)
_FORMATS: dict[DataType, str] = {
    DataType.BOOLEAN: "<B", DataType.INTEGER8: "<b", DataType.INTEGER16: "<h",
    DataType.INTEGER32: "<i", DataType.INTEGER64: "<q", DataType.UNSIGNED8: "<B",
    DataType.UNSIGNED16: "<H", DataType.UNSIGNED32: "<I", DataType.UNSIGNED64: "<Q",
    DataType.REAL32: "<f",
}
_SIGNED = {DataType.INTEGER8, DataType.INTEGER16, DataType.INTEGER32, DataType.INTEGER64}

#: (first, last, why) of the objects the master owns: reads pass, writes are refused
MASTER_OWNED: tuple[tuple[int, int, str], ...] = (
    (0x1005, 0x1005, "COB-ID SYNC: this master produces the SYNC on COB-ID 0x080"),
    (0x1017, 0x1017, "the producer heartbeat time the master set at connect for its liveness "
                     "watch"),
    (RPDO_COM, 0x1BFF, "the PDO parameters the master mapped and enabled at connect; a change "
                       "stops the cycle's samples"),
    (PROCESS_OUTPUT, PROCESS_OUTPUT, "the process output image belongs to the register "
                                     "handshake and the control bits: use ~/write_register "
                                     "or ~/set_control"),
    (SIM_RATE, SIM_ACTIVE, "the simulated station's fault objects: use ~/inject_fault, which "
                           "times and clears what it injects"),
)


def value_kind(data_type: DataType) -> str:
    """Which request/response field carries a value of ``data_type``: ``signed``,
    ``unsigned``, ``float`` or ``string``."""
    if data_type in _SIGNED:
        return "signed"
    if data_type is DataType.REAL32:
        return "float"
    if data_type is DataType.VISIBLE_STRING:
        return "string"
    return "unsigned"


def type_named(name: str) -> DataType | None:
    """The data type a request names (case-insensitive; "" = None: the EDS's).

    Raises ConfigError for a name that is none of the accepted ones.
    """
    name = name.strip().upper()
    if not name:
        return None
    try:
        return DataType[name]
    except KeyError:
        raise ConfigError(f"data type {name[:40]!r} is not one of "
                          f"{', '.join(t.name for t in DataType)} (empty: the EDS's type)") \
            from None


def decode(data_type: DataType, data: bytes) -> int | float | str:
    """The value of ``data`` as ``data_type``; ConfigError when the length does not fit."""
    if data_type is DataType.VISIBLE_STRING:
        return data.decode("latin-1").rstrip("\x00")
    fmt = _FORMATS[data_type]
    size = struct.calcsize(fmt)
    if len(data) != size:
        raise ConfigError(f"the object holds {len(data)} byte(s); {data_type.name} is {size}: "
                          "name the object's own type (or leave data_type empty)")
    (value,) = struct.unpack(fmt, data)
    return float(value) if data_type is DataType.REAL32 else int(value)


def encode(data_type: DataType, value: int | float | str) -> bytes:
    """``value`` as the bytes of ``data_type``; ConfigError when it does not fit the type."""
    if data_type is DataType.VISIBLE_STRING:
        try:
            return str(value).encode("latin-1")
        except UnicodeEncodeError:
            raise ConfigError("VISIBLE_STRING holds latin-1 characters only") from None
    fmt = _FORMATS[data_type]
    if data_type is DataType.REAL32:
        if not math.isfinite(float(value)) or abs(float(value)) > 3.4028234663852886e38:
            raise ConfigError(f"{value} is not a finite REAL32")
        return struct.pack(fmt, float(value))
    bits = 8 * struct.calcsize(fmt)
    low, high = ((-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if data_type in _SIGNED
                 else (0, 1 if data_type is DataType.BOOLEAN else (1 << bits) - 1))
    if not low <= int(value) <= high:
        raise ConfigError(f"{value} is outside {data_type.name} ({low}..{high})")
    return struct.pack(fmt, int(value))


def show(data_type: DataType, value: int | float | str) -> str:
    """A value for a message: hex and decimal for integers.

    :param data_type: the value's CANopen data type
    :param value: the value
    """
    if isinstance(value, str):
        return repr(value)
    if isinstance(value, float):
        return f"{value:g}"
    if data_type in _SIGNED:
        return str(value)
    return f"0x{value:X} ({value})"


class ObjectAccess:
    """Typed SDO access to the stations of one node, through its :class:`Bridge`.

    :param bridge: the node's facade: its joints, their stations' clients, REG_PARA1's path
    """

    def __init__(self, bridge: Bridge) -> None:
        self.bridge = bridge

    # -- where and what --------------------------------------------------------------------
    def station(self, node_id: int, joint: str) -> StationClient:
        """The client of station ``node_id`` (0: the station of ``joint``, empty = the first).

        Raises ConfigError for an unknown joint or a node id that is none of the node's
        stations.
        """
        if node_id == 0:
            return self.bridge.client_of(self.bridge.joint(joint).name)
        clients: dict[int, StationClient] = {}
        for name in self.bridge.joints:
            client = self.bridge.client_of(name)
            clients.setdefault(int(client.node_id), client)
        if node_id not in clients:
            raise ConfigError(f"node id {node_id} is not a station of this node (stations: "
                              f"{sorted(clients)}; 0 = the station of the joint)")
        return clients[node_id]

    def slot_joint(self, client: StationClient, slot: int) -> Joint | None:
        """The configured joint whose module sits in ``slot`` of ``client``'s station."""
        for joint in self.bridge.joints.values():
            if joint.slot == slot and self.bridge.client_of(joint.name) is client:
                return joint
        return None

    @staticmethod
    def entry(client: StationClient, index: int, subindex: int) -> DictionaryEntry | None:
        """The dictionary's variable of ``index:subindex`` (None if the EDS has none, or the
        client has no dictionary: a listen-only one)."""
        node = getattr(client, "node", None)  # canopen's RemoteNode of a BridgeClient
        if node is None:
            return None
        try:
            obj = node.object_dictionary[index]
            entry: DictionaryEntry = obj if not hasattr(obj, "subindices") else obj[subindex]
            return entry
        except (KeyError, ValueError):
            return None

    def _type(self, client: StationClient, index: int, subindex: int, named: DataType | None
              ) -> tuple[DataType | None, str]:
        """The type to use (the named one, else the EDS's) and the object's EDS name."""
        var = self.entry(client, index, subindex)
        name = f" ({var.name})" if var is not None else ""
        if named is not None:
            return named, name
        if var is None or var.data_type is None:  # (None: an EDS entry without DataType)
            return None, name
        try:
            return DataType(var.data_type), name
        except ValueError:
            raise ConfigError(f"the EDS gives 0x{index:04X}:{subindex:02X} data type "
                              f"0x{var.data_type:04X}, which this service does not decode: "
                              "name a type") from None

    @staticmethod
    def _sdo(client: StationClient, index: int, subindex: int, write: bool) -> RawSdo:
        """The client's SDO access; the client's own refusal when it has none (a listen-only
        client raises "... refused: listen-only: another master drives this bus")."""
        sdo: RawSdo | None = getattr(client, "sdo", None)  # a connected BridgeClient's
        if sdo is None:
            if write:
                client.write_object(index, subindex, b"")
            else:
                client.read_object(index, subindex)
            raise BusError("the master is not connected")
        return sdo

    # -- the two operations ----------------------------------------------------------------
    def read(self, node_id: int, joint: str, index: int, subindex: int, data_type: str
             ) -> tuple[DataType, int | float | str, str]:
        """Upload ``index:subindex``: (type, value, sentence).

        Raises SdoAbortError (the station's abort code and its CiA 301 meaning),
        GatewayUnavailable, BusError (listen-only) or ConfigError.

        :param node_id: the station (0: the station of ``joint``)
        :param joint: the joint naming the station when ``node_id`` is 0 (empty: the first)
        :param index: the object's index
        :param subindex: its subindex
        :param data_type: the type to decode with (empty: the EDS's)
        """
        named = type_named(data_type)
        client = self.station(node_id, joint)
        sdo = self._sdo(client, index, subindex, write=False)
        dtype, name = self._type(client, index, subindex, named)
        data = sdo.upload(index, subindex)
        where = f"0x{index:04X}:{subindex:02X}{name} of node {client.node_id}"
        if dtype is None:
            raise ConfigError(f"{where} is not in the EDS, so its type is unknown: name a "
                              f"data_type (read {len(data)} byte(s): {data.hex()})")
        value = decode(dtype, data)
        return dtype, value, f"{where} = {show(dtype, value)} {dtype.name}"

    def write(self, node_id: int, joint: str, index: int, subindex: int, data_type: str,
              value_of: Callable[[DataType], int | float | str]) -> tuple[DataType, str]:
        """Download ``value_of(type)`` to ``index:subindex``: (type, sentence); see the module
        text for the objects that take the node's own path or are refused. ``value_of`` picks
        the value once the type is known (named, or the EDS's).

        Raises SdoAbortError, GatewayUnavailable, BusError, ConfigError (a refusal, or a value
        the type or the module's rules do not allow).

        :param node_id: the station (0: the station of ``joint``)
        :param joint: the joint naming the station when ``node_id`` is 0 (empty: the first)
        :param index: the object's index
        :param subindex: its subindex
        :param data_type: the type to encode with (empty: the EDS's)
        """
        named = type_named(data_type)
        client = self.station(node_id, joint)
        where = f"0x{index:04X}:{subindex:02X}"
        for first, last, why in MASTER_OWNED:
            if first <= index <= last:
                raise ConfigError(f"writing {where} is refused: {why}")
        sdo = self._sdo(client, index, subindex, write=True)
        dtype, name = self._type(client, index, subindex, named)
        where += f"{name} of node {client.node_id}"
        if dtype is None:
            raise ConfigError(f"{where} is not in the EDS, so its type is unknown: name a "
                              "data_type")
        value = value_of(dtype)
        data = encode(dtype, value)
        target = self.slot_joint(client, subindex)
        if index == ENCODER_CONFIG and target is not None:
            if len(data) != 4:
                raise ConfigError(f"{where} is UNSIGNED32 (REG_PARA1); {dtype.name} is "
                                  f"{len(data)} byte(s)")
            return dtype, self.bridge.change_para1(
                target.name, int.from_bytes(data, "little"), "~/sdo_write")
        if index == PRESET and target is not None:
            self._write_preset(sdo, target, index, subindex, data)
        else:
            sdo.download(index, subindex, data)
        text = f"{where} <- {show(dtype, value)} {dtype.name}"
        if index in CAM_OBJECTS and target is not None:
            target.frames.set_cam(read_cam(lambda i: int(client.read_object(i, target.slot))))
            text += f"; {target.name}'s CAM state follows"
        return dtype, text

    @staticmethod
    def _write_preset(sdo: RawSdo, joint: Joint, index: int, subindex: int, data: bytes) -> None:
        """0x6810 = REG_OFFSET moves the zero point: no sample across the write enters the
        velocity estimate (as ``Bridge.set_preset``)."""
        estimator = joint.velocity
        estimator.reset(after=math.inf, hold=True)
        try:
            sdo.download(index, subindex, data)
        finally:
            estimator.reset(after=wire_now() + 0.05, hold=True)


__all__ = ["MASTER_OWNED", "ObjectAccess", "decode", "encode", "type_named", "value_kind"]
