"""The replay served to Foxglove: a WebSocket server whose time line Foxglove drives.

``replay --foxglove-port 8765`` starts a Foxglove WebSocket server (foxglove-sdk, subprotocol
``foxglove.sdk.v1``) beside, or with ``--no-ros`` instead of, the ROS publishers. Every played
topic is one channel with the schema stored in the bag (``ros2msg``, the .msg text and its
dependencies) and the recorded CDR bytes unchanged, stamped with the recorded log time, as the
node's live view (ros/liveview.py) serves a live session. The server advertises the bag's time
range and the PlaybackControl capability, so Foxglove shows a time line: play, pause, a seek
and a speed change arrive as PlaybackControlRequests and move the same time line as the keys
and the ``~/pause`` ... ``~/seek`` services (record/player_state.py); changes made by those
are broadcast as PlaybackState to every client, and the bag time about 20 times a second.
The server binds to 127.0.0.1 unless ``--foxglove-address`` says otherwise.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import TYPE_CHECKING, Any, cast

from mcap.records import Message

from ssi_bridge.exceptions import RecordingError
from ssi_bridge.record.player_state import PlayerState
from ssi_bridge.record.reader import Bag

if TYPE_CHECKING:  # the SDK is imported when a view starts (an optional dependency)
    from foxglove import Channel
    from foxglove.websocket import (
        PlaybackControlRequest,
        PlaybackState,
        ServerListener,
        WebSocketServer,
    )

logger = logging.getLogger(__name__)

#: at most this often the bag time is broadcast while messages flow (s)
TIME_PERIOD = 0.05


class _Listener:
    """Foxglove ServerListener: playback control requests move the time line."""

    def __init__(self, view: ReplayView) -> None:
        self._view = view

    def on_playback_control_request(self, request: PlaybackControlRequest) -> PlaybackState:
        return self._view.control(request)


class ReplayView:
    """The Foxglove server of one replay; :meth:`sink` is the Player's sink for its records.

    Raises RecordingError when the server cannot listen (port in use, bad address) or the
    Foxglove SDK is not installed.

    :param bag: the bag (its topics' schemas are advertised)
    :param topics: the topics served
    :param state: the replay's time line Foxglove drives
    :param address: the address to listen on
    :param port: the TCP port (0: any free one, see ``port``)
    :param name: the server's name shown in Foxglove
    """

    def __init__(self, bag: Bag, topics: list[str], state: PlayerState, address: str,
                 port: int, name: str = "ssi_bridge replay") -> None:
        try:
            import foxglove
            from foxglove.websocket import Capability
        except ImportError as err:
            raise RecordingError(f"--foxglove-port needs the Foxglove SDK ({err}): "
                                 "pip install foxglove-sdk==0.30.3") from err
        self.state = state
        self._local = threading.local()
        self._last_time = 0.0
        self._context = foxglove.Context()
        try:
            server = foxglove.start_server(
                name=name, host=address, port=port, context=self._context,
                capabilities=[Capability.Time, Capability.PlaybackControl],
                # the SDK calls the callbacks a listener has (ServerListener's are optional)
                server_listener=cast("ServerListener", _Listener(self)),
                playback_time_range=(state.first_ns, state.end_ns))
        except (RuntimeError, ValueError, OSError) as err:
            reason = str(err).removeprefix("FoxgloveError: ")
            raise RecordingError(f"--foxglove-port {port}: cannot listen on "
                                 f"{address}:{port}: {reason}") from err
        self.server: WebSocketServer | None = server
        self.port = int(server.port)
        self.channels: dict[str, Channel] = {}
        for topic in topics:
            recorded = bag.topics[topic]
            schema = foxglove.Schema(name=recorded.type,
                                     encoding=recorded.schema_encoding or "ros2msg",
                                     data=recorded.schema_data)
            self.channels[topic] = foxglove.Channel(topic, message_encoding="cdr",
                                                    context=self._context, schema=schema)
        state.on_change(self._changed)

    def sink(self, topic: str, record: Message) -> None:
        """Send one published record to the subscribed clients; broadcast the bag time.

        :param topic: the record's topic
        :param record: the MCAP message record as published
        """
        channel = self.channels.get(topic)
        if channel is not None and channel.has_sinks():
            channel.log(record.data, log_time=record.log_time)
        now = time.monotonic()
        server = self.server
        if server is not None and now - self._last_time >= TIME_PERIOD:
            self._last_time = now
            server.broadcast_time(record.log_time)

    def playback_state(self, request_id: str | None = None, did_seek: bool = False,
                       ) -> PlaybackState:
        """The time line as Foxglove's PlaybackState.

        :param request_id: the request this answers (None: unsolicited)
        :param did_seek: the time line jumped
        """
        from foxglove.websocket import PlaybackState, PlaybackStatus

        snap = self.state.snapshot()
        status = (PlaybackStatus.Ended if snap.ended else
                  PlaybackStatus.Paused if snap.paused else PlaybackStatus.Playing)
        return PlaybackState(status=status, current_time=snap.bag_ns,
                             playback_speed=snap.rate, did_seek=did_seek,
                             request_id=request_id)

    def control(self, request: PlaybackControlRequest) -> PlaybackState:
        """Apply a PlaybackControlRequest (seek, speed, play/pause); answer the new state.

        :param request: what Foxglove asked; never raises (a failure is logged and the state
            answered unchanged)
        """
        from foxglove.websocket import PlaybackCommand

        self._local.in_request = True
        try:
            did_seek = request.seek_time is not None
            if request.seek_time is not None:
                self.state.seek(request.seek_time)
            speed = float(request.playback_speed)
            if speed > 0 and abs(speed - self.state.rate) > 1e-6:
                self.state.set_rate(speed)
            if request.playback_command == PlaybackCommand.Play:
                if not did_seek and self.state.snapshot().ended:
                    self.state.seek(self.state.start_ns)  # play at the end: from the start
                    did_seek = True
                self.state.resume()
            else:
                self.state.pause()
            logger.info("Foxglove: %s%s at %.2fx", request.playback_command.name.lower(),
                        " after a seek" if did_seek else "", self.state.rate)
            return self.playback_state(request.request_id, did_seek)
        except Exception as err:  # noqa: BLE001 - a callback of the SDK must not raise
            logger.error("Foxglove playback request %s refused: %s", request.request_id, err)
            return self.playback_state(request.request_id)
        finally:
            self._local.in_request = False

    def _changed(self, what: str) -> None:
        """A control outside Foxglove (keys, services, the end) changed the time line."""
        server = self.server
        if server is None or getattr(self._local, "in_request", False):
            return
        server.broadcast_playback_state(self.playback_state(None, what == "seek"))
        server.broadcast_time(self.state.snapshot().bag_ns)

    def stop(self) -> None:
        """Close the channels and the server; safe to call twice."""
        channels, self.channels = self.channels, {}
        for channel in channels.values():
            channel.close()
        server, self.server = self.server, None
        if server is not None:
            server.stop()
