"""The master's watch on the gateway: heartbeat consumer, SDO probe and re-configuration.

CiA 301 heartbeat consumer: the gateway counts as silent after ``heartbeat_timeout`` without a
heartbeat (4 producer periods, 0x1017 as the client configured it). A boot-up message (state
0) or a heartbeat in any state but OPERATIONAL (the station was reset or restarted, 000
chapter 4: it boots into PRE-OPERATIONAL with every PDO invalid) asks the supervisor thread to
run ``configure()`` again, except one that still shows the state from before the master's NMT
start within ``heartbeat_timeout`` after it: a device may have had that heartbeat queued for
sending (a CAN controller's transmit mailbox) when the command came, so it is no state change.
While no heartbeat comes at all the gateway is probed over SDO
every 5 periods: a restarted station has its heartbeat producer off again (0x1017 = 0), so it
only shows up by answering.

The master owns the NMT state of its stations (CiA 301 §7.2.8.2.1: one NMT master per
network): a heartbeat in STOPPED or PRE-OPERATIONAL, put there by another node's NMT command or
by the station itself, wakes the supervisor at once, which sends NMT start alone
(``start_again()``: such a command keeps the object dictionary, §7.2.8.2.1) and then reads the
PDOs' COB-IDs back; only when they are no longer the configured ones does ``configure()`` run
(NMT "enter PRE-OPERATIONAL" first, a STOPPED node serves no SDO). Either is counted in
``nmt_restarts``. A heartbeat whose state is none of CiA 301's (0 boot-up,
4 STOPPED, 5 OPERATIONAL, 127 PRE-OPERATIONAL, §7.2.8.3.2.1) is no heartbeat: it is counted
(``invalid_nmt_states``), logged at most once per second, and changes nothing. No exception
of one supervisor round ends the thread: it is counted (``supervisor_errors``), logged at most
once per second, and the next round runs.

Clocks: every interval here (heartbeat age, the time since the NMT start, probe times, how
long a gateway has been silent) runs on the monotonic clock (``clock``, ``time.monotonic``):
a heartbeat's arrival is noted on it when the frame is handled, so a step of the wall clock
(NTP, an operator) neither silences a live gateway nor keeps a silent one alive. Wire time
(``base/timebase.py``, CLOCK_REALTIME) stays what it is, the stamp of frames:
:attr:`Liveness.last_heartbeat` is the last heartbeat's frame time, and the receive path's
lag is measured in it (``wire_clock`` against ``ReceiveWatch.seen_until``), one clock in
one difference.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Protocol

from ssi_bridge.base.rate_log import RateLimitedLog
from ssi_bridge.base.rx_guard import raised_at
from ssi_bridge.client.bus import ReceiveWatch
from ssi_bridge.client.samples import ClientCounters
from ssi_bridge.exceptions import SsiBridgeError
from ssi_bridge.base.timebase import wire_now
from ssi_bridge.protocol.dictionary import (
    NMT_STATE_BOOTUP, NMT_STATE_OPERATIONAL, NMT_STATE_PRE_OPERATIONAL, NMT_STATE_STOPPED,
    NMT_STATES,
)

logger = logging.getLogger(__name__)

HEARTBEAT_OBJECT = 0x1017
#: while a gateway stays silent, one summary line at most this often (s)
SILENT_SUMMARY_S = 10.0
#: the SDO probe of a silent gateway runs with this flag set in its thread: canopen's own
#: lines about its unanswered transfer are then dropped (the silence is said here, quietly)
_PROBING = threading.local()


class _QuietProbe(logging.Filter):
    """Drops canopen's SDO client lines logged by a probe of a silent gateway."""

    def filter(self, record: logging.LogRecord) -> bool:
        return not getattr(_PROBING, "active", False)


def _install_quiet_probe() -> None:
    sdo_log = logging.getLogger("canopen.sdo.client")
    if not any(isinstance(f, _QuietProbe) for f in sdo_log.filters):
        sdo_log.addFilter(_QuietProbe())


_install_quiet_probe()
#: heartbeat states in which the master starts its station again
NOT_STARTED = (NMT_STATE_STOPPED, NMT_STATE_PRE_OPERATIONAL)


class Supervised(Protocol):
    """What the supervisor reads of and does to its station's client (``BridgeClient``)."""

    node_id: int
    heartbeat_ms: int
    heartbeat_timeout: float
    counters: ClientCounters
    #: the receive path's watch (``seen_until()``), None before connect
    bus: ReceiveWatch | None

    @property
    def gateway_alive(self) -> bool:
        """True while the station's heartbeat is current."""

    def read_object(self, index: int, subindex: int = 0) -> int | float | bytes | str:
        """One SDO upload (raises SsiBridgeError).

        :param index: the object's index
        :param subindex: its subindex
        """

    def configure(self) -> None:
        """Configure the station again (raises SsiBridgeError)."""

    def start_again(self) -> bool:
        """NMT start alone; False when the PDOs need ``configure()`` (raises SsiBridgeError)."""


class Liveness:
    """Heartbeat state of one station's client and its supervisor thread.

    ``clock`` measures every interval (monotonic seconds); ``wire_clock`` is the wire time
    the bus stamps frames in (``ReceiveWatch.seen_until``), used only to measure how far the
    receive path lags. Both are injectable for tests.
    """

    def __init__(self, client: Supervised, clock: Callable[[], float] = time.monotonic,
                 wire_clock: Callable[[], float] = wire_now) -> None:
        self._client = client
        self._clock = clock
        self._wire_clock = wire_clock
        #: wire time of the last heartbeat frame (its timestamp): a stamp, for the record
        self.last_heartbeat = 0.0
        #: monotonic time the last heartbeat was handled, or the gateway started (configure)
        self.heard_at = float("-inf")
        #: NMT state of the last heartbeat, None before the first
        self.state: int | None = None
        #: True while configure() runs (its own NMT commands must not re-trigger it)
        self.configuring = False
        #: monotonic time at which the last configure() started the gateway (NMT OPERATIONAL)
        self.started_at = float("-inf")
        self._reconfigure = threading.Event()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._was_alive = False
        self._log = RateLimitedLog(logger)
        self._summary = RateLimitedLog(logger, SILENT_SUMMARY_S)
        #: monotonic time the gateway went silent (None: it is not), probes unanswered since
        self._silent_since: float | None = None
        self._unanswered = 0
        self._next_probe = float("-inf")
        #: the heartbeat state that asked for the pending re-configuration (None: other cause)
        self._restart_from: int | None = None

    def started(self) -> None:
        """``configure()`` started the gateway (NMT OPERATIONAL) now: it counts as heard."""
        self.heard_at = self.started_at = self._clock()

    def alive(self) -> bool:
        """True unless the wire was watched for a heartbeat timeout without a heartbeat.

        The heartbeat's age is monotonic time since it was handled. Silence counts only
        as far as this side has handled the wire: the receive path's lag (wire time now
        minus ``ReceiveWatch.seen_until``, the wire time up to which every frame has been
        handled) is taken off the age, so a stalled process whose receive queue still holds
        heartbeats is not "gateway silent"; a real silence shows once the receive thread
        finds the queue empty (within its 0.05 s wake-up) past the timeout. The heartbeat
        was on the wire before it was handled, so the wire watched since it is at least
        ``age - lag``. A lag below 0 (the wall clock stepped back since the receive path
        last noted it) counts as none: the age alone decides.
        """
        timeout = self._client.heartbeat_timeout
        age = self._clock() - self.heard_at
        if age <= timeout:
            return True
        bus = self._client.bus
        if bus is None:
            return False
        lag = self._wire_clock() - bus.seen_until()
        return age - max(lag, 0.0) <= timeout

    def on_heartbeat_frame(self, can_id: int, data: bytearray, timestamp: float) -> None:
        """The heartbeat frame (network thread): its receive time, then the NMT state.

        :param can_id: 0x700 + the gateway's node id
        :param data: the heartbeat's byte (the NMT state)
        :param timestamp: its wire time (s)
        """
        if not data:
            return
        state = data[0] & 0x7F
        if state not in NMT_STATES:
            self._client.counters.invalid_nmt_states += 1
            self._log.warning("invalid_nmt_state", "gateway node %d: heartbeat 0x%03X [%s] "
                              "carries NMT state %d, none of CiA 301's (0, 4, 5, 127): ignored",
                              self._client.node_id, can_id, data.hex(" "), state)
            return
        self.last_heartbeat = timestamp
        self.on_heartbeat(state)

    def start(self) -> None:
        """Start the supervisor thread (after the first configuration)."""
        self._stop.clear()
        self._reconfigure.clear()
        self._thread = threading.Thread(target=self._supervise, daemon=True,
                                        name=f"bridge-supervisor-{self._client.node_id}")
        self._thread.start()

    def stop(self, timeout: float) -> None:
        """Stop the supervisor thread, waiting up to ``timeout`` s (not from itself)."""
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=timeout)
        self._thread = None

    def reconfigure(self) -> None:
        """Ask the supervisor thread to configure the station again (e.g. the bus is back)."""
        self._reconfigure.set()

    def on_heartbeat(self, state: int) -> None:
        """A heartbeat in NMT ``state`` is handled now (network thread)."""
        at = self.heard_at = self._clock()
        self.state = state
        if state == NMT_STATE_BOOTUP:
            self._client.counters.restarts += 1
            logger.warning("gateway node %d booted (restart?); re-configuring",
                           self._client.node_id)
            self._reconfigure.set()
        elif state != NMT_STATE_OPERATIONAL and not self.configuring:
            if at - self.started_at <= self._client.heartbeat_timeout:
                return  # sent before the NMT start took effect (see the module docstring)
            if not self._reconfigure.is_set():
                self._restart_from = state
            self._reconfigure.set()

    def _supervise(self) -> None:
        """Rounds every heartbeat period, or at once when a re-configuration is asked for."""
        client = self._client
        period = max(client.heartbeat_ms / 1000.0, 0.02)
        self._next_probe = float("-inf")
        while not self._stop.is_set():
            self._reconfigure.wait(period)
            if self._stop.is_set():
                break
            try:
                if not self._round(period):
                    self._stop.wait(period)  # a failed configuration: retried next period
            except Exception as err:  # noqa: BLE001 - no round may end the thread
                client.counters.supervisor_errors += 1
                self._log.error("supervisor_error", "%s: round failed, the thread goes on: "
                                "%r at %s", threading.current_thread().name, err, raised_at(err))
                self._stop.wait(period)

    def _round(self, period: float) -> bool:
        """One supervisor round: liveness, SDO probe, re-configuration; False if that failed."""
        client = self._client
        alive = client.gateway_alive
        if self._was_alive and not alive:
            logger.warning("gateway node %d silent: no heartbeat for %.3f s",
                           client.node_id, client.heartbeat_timeout)
            self._silent_since, self._unanswered = self._clock(), 0
        elif alive and not self._was_alive and self._silent_since is not None:
            logger.info("gateway node %d heard again after %.1f s of silence",
                        client.node_id, self._clock() - self._silent_since)
            self._silent_since = None
        self._was_alive = alive
        if not alive and self._clock() >= self._next_probe and not self._reconfigure.is_set():
            self._next_probe = self._clock() + 5 * period
            _PROBING.active = True
            try:
                client.read_object(HEARTBEAT_OBJECT)
                self._reconfigure.set()  # it answers but sends no heartbeat: restarted
            except SsiBridgeError:
                client.counters.timeouts += 1
                self._unanswered += 1
                silent_s = (self._clock() - self._silent_since
                            if self._silent_since is not None else 0.0)
                if silent_s >= SILENT_SUMMARY_S:
                    self._summary.warning(
                        "still_silent", "gateway node %d still silent after %.0f s (%d SDO "
                        "probes unanswered)", client.node_id, silent_s, self._unanswered)
            finally:
                _PROBING.active = False
        if not self._reconfigure.is_set() or self._stop.is_set():
            return True
        self._reconfigure.clear()
        restart_from, self._restart_from = self._restart_from, None
        try:
            if not (restart_from in NOT_STARTED and client.start_again()):
                client.configure()
        except Exception as err:
            # asked for again: the next round retries (an unexpected error is counted there)
            if restart_from is not None and self._restart_from is None:
                self._restart_from = restart_from
            self._reconfigure.set()
            if not isinstance(err, SsiBridgeError):
                raise
            self._log.warning("reconfigure", "gateway node %d re-configuration failed: %s",
                              client.node_id, err)
            return False
        if restart_from in NOT_STARTED:
            client.counters.nmt_restarts += 1
            self._log.warning("nmt_restart", "gateway node %d was %s (heartbeat; not by this "
                              "master): started again", client.node_id,
                              NMT_STATES[restart_from])
        return True
