"""Commission a bus: listen, scan, identify, read REG_PARA1, sample, infer; one result.

:func:`commission` is the whole run on one python-can bus (a :class:`BusConfig` it opens, or
an open bus it takes over). It writes nothing to a station but the register read handshake
(REG_RD_ADR, set back afterwards) and SYNC, unless ``configure`` asks for the corrected
REG_PARA1 to be written. With another master on the bus it stops after listening
(:attr:`Result.refusal`), or with ``listen_only`` only watches (``listen_only.py``).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field

import can
import canopen

from ssi_bridge.base.buses import take_bus
from ssi_bridge.client.bus import MasterNetwork, open_bus
from ssi_bridge.client.handshake import Handshake
from ssi_bridge.client.sdo import SdoAccess
from ssi_bridge.commission.analyze import SlotResult, analyze
from ssi_bridge.commission.discover import (Heard, Identity, SlotProbe, find_slots, identify,
                                            listen, note, scan)
from ssi_bridge.commission.sample import STEP_TIMEOUT, SdoImagePort, read_register, sample
from ssi_bridge.exceptions import BusError, RegisterError, SsiBridgeError
from ssi_bridge.protocol.diagnostics import DIAG_TEXT, Diag
from ssi_bridge.protocol.dictionary import SYNC_COB_ID
from ssi_bridge.protocol.registers import Reg
from ssi_bridge.protocol.settings import BusConfig

logger = logging.getLogger(__name__)
#: Encoder Diag: the diagnostics byte of each slot (000 Table 27)
ENCODER_DIAG = 0x5804
Progress = Callable[[str], None]


@dataclass(frozen=True)
class Options:
    """How long and where to look (the command line's options)."""

    #: sampling time (s)
    seconds: float = 3.0
    #: listening window before anything is sent (s)
    listen: float = 0.5
    #: node ids the SDO scan asks
    node_ids: tuple[int, ...] = tuple(range(1, 128))
    #: answer window of the SDO scan (s)
    scan_window: float = 0.3
    #: bound of one SDO transfer (s)
    sdo_timeout: float = 0.3
    listen_only: bool = False
    #: write the corrected REG_PARA1 (the only change the tool makes)
    configure: bool = False

    def __post_init__(self) -> None:
        if not self.seconds > 0 or self.listen < 0 or not self.sdo_timeout > 0:
            raise ValueError("seconds and sdo_timeout must be > 0, listen >= 0")
        if not self.node_ids or not all(1 <= n <= 127 for n in self.node_ids):
            raise ValueError(f"node ids {self.node_ids}: 1-127")


@dataclass
class StationResult:
    """One XN-GW-CANOPEN: identity, its slots and what each holds."""

    identity: Identity
    probes: list[SlotProbe] = field(default_factory=list)
    slots: list[SlotResult] = field(default_factory=list)
    error: str | None = None


@dataclass
class Result:
    """The whole run."""

    heard: Heard
    refusal: str | None = None
    listen_only: bool = False
    stations: list[StationResult] = field(default_factory=list)
    others: list[Identity] = field(default_factory=list)
    #: nodes that were heard or answered the scan, then fell silent
    silent: list[str] = field(default_factory=list)
    #: REG_PARA1 writes done under ``configure``
    written: list[str] = field(default_factory=list)
    #: the listen-only observation (``listen_only.Observation``)
    observed: object | None = None

    @property
    def slot_results(self) -> list[SlotResult]:
        """Every analysed slot of every station."""
        return [s for st in self.stations for s in st.slots]


class _Garbage(can.Listener):
    """Counts non-CANopen frames while the network runs (the heard record of the run)."""

    def __init__(self, heard: Heard) -> None:
        self.heard = heard

    def on_message_received(self, msg: can.Message) -> None:
        if msg.is_error_frame or msg.is_extended_id or msg.is_remote_frame:
            note(self.heard, msg)

    def on_error(self, exc: Exception) -> None:
        self.heard.garbage[f"undecodable frame ({type(exc).__name__})"] += 1


def commission(bus: BusConfig | can.BusABC, options: Options,
               progress: Progress | None = None) -> Result:
    """Run the commissioning on ``bus``; raises BusError only when the bus cannot be opened.

    :param bus: the bus's configuration (opened here) or an open bus (taken over)
    :param options: node ids, sampling time, listen-only, ...
    :param progress: called with one line per step, for a person watching
    :returns: what was heard, found and inferred (a refused run says why in ``refusal``)
    :raises BusError: the bus cannot be opened
    """
    say = progress or (lambda text: None)
    raw = take_bus(bus, "commission", open_bus)
    say(f"listening {options.listen:g} s for heartbeats and other masters")
    heard = listen(raw, options.listen)
    result = Result(heard, listen_only=options.listen_only)
    if heard.masters and not options.listen_only:
        result.refusal = heard.master_line()
        raw.shutdown()
        return result
    if options.listen_only:
        from ssi_bridge.commission.listen_only import observe
        try:
            result.observed = observe(raw, heard, options.seconds, say)
        finally:
            raw.shutdown()
        return result
    ids = list(options.node_ids)
    say(f"SDO scan of node ids {ids[0]}-{ids[-1]} ({len(ids)} ids)" if len(ids) > 1
        else f"SDO scan of node id {ids[0]}")
    try:
        answered = scan(raw, ids, options.scan_window)
    except BusError:
        raw.shutdown()
        raise
    network = MasterNetwork(raw)
    network.start(_Garbage(heard), canopens_too=True)
    try:
        _run(network, heard, answered, options, result, say)
    finally:
        network.disconnect()
    return result


def _run(network: MasterNetwork, heard: Heard, answered: set[int], options: Options,
         result: Result, say: Progress) -> None:
    def send_sync() -> None:
        try:
            network.send_message(SYNC_COB_ID, b"")
        except can.CanError as err:
            raise BusError(f"SYNC not sent: {err}") from err

    targets: list[tuple[SdoImagePort, int, int]] = []
    where: dict[tuple[int, int], tuple[StationResult, int | None, int | None]] = {}
    for node_id in sorted(answered | set(heard.heartbeats)):
        sdo = SdoAccess(node_id, canopen.ObjectDictionary(), options.sdo_timeout)
        network.add_node(sdo.node)
        try:
            ident = identify(sdo)
        except SsiBridgeError as err:
            result.silent.append(f"node {node_id}: heard, but no SDO answer ({err})")
            continue
        if ident.refusal:
            result.others.append(ident)
            say(f"node {node_id}: {ident.refusal}")
            continue
        station = StationResult(ident)
        result.stations.append(station)
        try:
            station.probes = find_slots(sdo)
        except SsiBridgeError as err:
            station.error = f"slots not read: {err}"
            continue
        ssi = [p for p in station.probes if p.para1 is not None]
        say(f"node {node_id}: XN-GW-CANOPEN, XN-1SSI in slot(s) "
            f"{', '.join(str(p.slot) for p in ssi) or 'none'}")
        port = SdoImagePort(sdo, send_sync)
        for probe in ssi:
            try:
                para1: int | None = read_register(port, probe.slot, Reg.REG_PARA1)
            except (SsiBridgeError, RegisterError) as err:
                para1 = None
                logger.info("node %d slot %d: REG_PARA1 handshake: %s", node_id, probe.slot,
                            err)
            targets.append((port, node_id, probe.slot))
            where[(node_id, probe.slot)] = (station, para1, probe.para1)
    if targets:
        found = sample(targets, send_sync, options.seconds, say)
    else:
        found = []
    for (port, _, _), got in zip(targets, found):
        station, para1, para1_object = where[(got.node_id, got.slot)]
        res = analyze(got, para1, para1_object)
        res.diag_now = diagnostics_now(port.sdo, got.slot)
        station.slots.append(res)
    if options.configure:
        _configure(targets, result, send_sync)


def diagnostics_now(sdo: SdoAccess, slot: int) -> list[str] | None:
    """The slot's diagnostics byte (object 0x5804 = REG_DIAG1, 000 Table 27) in the manual's
    words ([] when none is set, None when it cannot be read).

    :param sdo: SDO access to the gateway
    :param slot: the module's slot
    """
    try:
        value = int.from_bytes(sdo.upload(ENCODER_DIAG, slot)[:1] or b"\0", "little")
    except SsiBridgeError:
        return None
    return [DIAG_TEXT[bit] for bit in Diag if value & bit]


def _configure(targets: list[tuple[SdoImagePort, int, int]], result: Result,
               send_sync: Callable[[], None]) -> None:
    """Write the corrected REG_PARA1 of each joint that needs one (``--configure``)."""
    ports = {(node, slot): port for port, node, slot in targets}
    for res in result.slot_results:
        if not res.joint or res.para1_joint == res.para1:
            continue
        port = ports[(res.node_id, res.slot)]
        assert res.para1_joint is not None
        try:
            port.load(res.slot)
            Handshake(port, STEP_TIMEOUT, 3 * STEP_TIMEOUT).write(res.slot, Reg.REG_PARA1,
                                                                  res.para1_joint)
            result.written.append(f"node {res.node_id} slot {res.slot}: REG_PARA1 "
                                  f"0x{res.para1_joint:08X} written")
        except SsiBridgeError as err:
            result.written.append(f"node {res.node_id} slot {res.slot}: REG_PARA1 not "
                                  f"written: {err}")


__all__ = ["ENCODER_DIAG", "Options", "Result", "StationResult", "commission", "diagnostics_now"]
