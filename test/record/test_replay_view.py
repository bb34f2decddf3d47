"""replay --foxglove-port: a plain WebSocket client drives the replay's time line as Foxglove does.

The client speaks the Foxglove WebSocket protocol itself (subprotocol ``foxglove.sdk.v1``):
JSON serverInfo / advertise / subscribe; binary Message Data (opcode 0x01: subscription id u32,
log time u64, payload), Time (0x02: u64), PlaybackState (0x05: status u8, current time u64,
speed f32, did_seek u8, request id u32 length + bytes) from the server, and the client's
PlaybackControlRequest (0x03: command u8 (0 play, 1 pause), speed f32, had_seek u8, seek time
u64, request id u32 length + bytes). Payloads are decoded with the advertised ros2msg schema
(mcap_ros2's decoder), as Foxglove does.
"""

from __future__ import annotations

import asyncio
import json
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from .conftest import T0, joint_states_bag

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
MESSAGE_DATA = struct.Struct("<BIQ")
PLAYBACK_STATE = struct.Struct("<BBQfBI")
N, PERIOD_NS = 400, 10_000_000          # a 4 s session at 100 Hz
PLAY, PAUSE = 0, 1
PLAYING, PAUSED, ENDED = 0, 1, 3


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return joint_states_bag(tmp_path_factory.mktemp("view") / "four_s", N, period_ns=PERIOD_NS)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def control(command: int, speed: float, seek_ns: int | None, request_id: str) -> bytes:
    """A PlaybackControlRequest as the Foxglove app sends it."""
    rid = request_id.encode()
    return struct.pack("<BBfBQI", 0x03, command, speed, seek_ns is not None, seek_ns or 0,
                       len(rid)) + rid


class Client:
    """One connection: subscribes to /joint_states, keeps what arrives with its arrival time."""

    def __init__(self, ws: Any) -> None:
        self.ws = ws
        self.info: dict = {}
        self.messages: list[tuple[float, int, Any]] = []   # (arrival, log time, decoded)
        self.states: list[tuple[int, int, float, bool, str]] = []
        self.decode: Any = None

    async def subscribe(self) -> None:
        from mcap.records import Schema
        from mcap_ros2.decoder import DecoderFactory

        channel = None
        while channel is None:
            msg = json.loads(await asyncio.wait_for(self.ws.recv(), 20))
            if msg["op"] == "serverInfo":
                self.info = msg
            elif msg["op"] == "advertise":
                channel = next(c for c in msg["channels"] if c["topic"] == "/joint_states")
        schema = Schema(id=1, name=channel["schemaName"], encoding=channel["schemaEncoding"],
                        data=channel["schema"].encode())
        self.decode = DecoderFactory().decoder_for("cdr", schema)
        await self.ws.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": 7, "channelId": channel["id"]}]}))

    async def collect(self, seconds: float) -> None:
        """Receive for ``seconds``, sorting frames into messages and playback states."""
        deadline = time.monotonic() + seconds
        while (left := deadline - time.monotonic()) > 0:
            try:
                frame = await asyncio.wait_for(self.ws.recv(), left)
            except TimeoutError:
                return
            if isinstance(frame, str):
                continue
            if frame[0] == 0x01:
                _, _sub, log_time = MESSAGE_DATA.unpack_from(frame)
                self.messages.append((time.monotonic(), log_time,
                                      self.decode(frame[MESSAGE_DATA.size:])))
            elif frame[0] == 0x05:
                _, status, now, speed, seek, n = PLAYBACK_STATE.unpack_from(frame)
                rid = frame[PLAYBACK_STATE.size:PLAYBACK_STATE.size + n].decode()
                self.states.append((status, now, speed, bool(seek), rid))

    async def until_state(self, request_id: str, timeout: float = 10.0) -> tuple:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            found = [s for s in self.states if s[4] == request_id]
            if found:
                return found[0]
            await self.collect(0.05)
        raise AssertionError(f"no PlaybackState for {request_id}; got {self.states}")


def start_replay(bag: Path, port: int, *args: str) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-m", "ssi_bridge.tools.replay", str(bag),
                             "--foxglove-port", str(port), "--start-paused", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


async def connect(port: int, proc: subprocess.Popen[str]) -> Any:
    import websockets

    deadline = time.monotonic() + 30
    while True:
        try:
            return await websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=SUBPROTOCOLS,
                                            max_size=None, open_timeout=10)
        except OSError:
            assert proc.poll() is None, proc.communicate()[1]
            if time.monotonic() > deadline:
                raise
            await asyncio.sleep(0.2)


def test_foxglove_seeks_pauses_and_plays_at_twice_the_rate(session: Path) -> None:
    port = free_port()
    proc = start_replay(session, port, "--no-ros")
    try:
        asyncio.run(_scrub(port, proc))
    finally:
        proc.terminate()
        out, err = proc.communicate(timeout=30)
    assert "Traceback" not in err and "refused" not in err, err
    assert "Foxglove: play after a seek at 1.00x" in err and "Foxglove: pause" in err, err


async def _scrub(port: int, proc: subprocess.Popen[str]) -> None:
    ws = await connect(port, proc)
    client = Client(ws)
    async with ws:
        await client.subscribe()
        assert "playbackControl" in client.info["capabilities"], client.info
        assert client.info["dataStartTime"] == {"sec": T0 // 10**9, "nsec": 0}
        end = T0 + (N - 1) * PERIOD_NS
        assert client.info["dataEndTime"] == {"sec": end // 10**9, "nsec": end % 10**9}
        await client.collect(0.5)
        assert not client.messages, "started paused: nothing yet"

        # seek to the middle and play: the first message is the one recorded there
        middle = T0 + N // 2 * PERIOD_NS
        await ws.send(control(PLAY, 1.0, middle, "seek-1"))
        status, now, speed, did_seek, _ = await client.until_state("seek-1")
        assert (status, did_seek, speed) == (PLAYING, True, 1.0)
        assert middle <= now < middle + 500_000_000, "the answer says where the time line is"
        await client.collect(0.5)
        assert client.messages, "messages after the seek"
        first = client.messages[0]
        assert first[1] == middle
        stamp = first[2].header.stamp
        assert stamp.sec * 10**9 + stamp.nanosec == T0 + N // 2 * 1_000_000  # joint_state(200)
        assert first[2].position[0] == pytest.approx(0.001 * (N // 2))

        # pause: after what was under way, nothing for 1 s
        await ws.send(control(PAUSE, 1.0, None, "pause-1"))
        status, paused_at, *_ = await client.until_state("pause-1")
        assert status == PAUSED
        await client.collect(0.3)
        before = len(client.messages)
        await client.collect(1.0)
        assert len(client.messages) == before, "messages while paused"

        # resume at 2x: bag time runs twice as fast as the wall clock
        await ws.send(control(PLAY, 2.0, None, "play-2x"))
        status, _, speed, _, _ = await client.until_state("play-2x")
        assert (status, speed) == (PLAYING, 2.0)
        await client.collect(0.8)
        fast = client.messages[before:]
        assert len(fast) >= 40, f"{len(fast)} messages in 0.8 s at 2x of 100 Hz"
        assert fast[0][1] > client.messages[before - 1][1], "continues where it paused"
        rate = (fast[-1][1] - fast[0][1]) / 1e9 / (fast[-1][0] - fast[0][0])
        assert 1.4 < rate < 2.8, rate
        times = [m[1] for m in client.messages]
        assert times == sorted(times) and len(set(times)) == len(times)


def test_a_port_in_use_and_no_ros_without_foxglove_are_refused(session: Path) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        out = subprocess.run([sys.executable, "-m", "ssi_bridge.tools.replay", str(session),
                              "--foxglove-port", str(port), "--no-ros"],
                             capture_output=True, text=True, timeout=60, check=False)
    assert out.returncode == 2 and f"cannot listen on 127.0.0.1:{port}" in out.stderr, out.stderr
    out = subprocess.run([sys.executable, "-m", "ssi_bridge.tools.replay", str(session),
                          "--no-ros"], capture_output=True, text=True, timeout=60, check=False)
    assert out.returncode == 2 and "--no-ros needs --foxglove-port" in out.stderr, out.stderr


def test_at_the_end_the_replay_waits_and_play_starts_it_again(session: Path) -> None:
    port = free_port()
    proc = start_replay(session, port, "--no-ros")
    try:
        asyncio.run(_replay_the_end(port, proc))
        assert proc.poll() is None, "the replay keeps serving after the end"
    finally:
        proc.terminate()
        _, err = proc.communicate(timeout=30)
    assert "Traceback" not in err, err


async def _replay_the_end(port: int, proc: subprocess.Popen[str]) -> None:
    ws = await connect(port, proc)
    client = Client(ws)
    async with ws:
        await client.subscribe()
        near_end = T0 + (N - 20) * PERIOD_NS
        await ws.send(control(PLAY, 1.0, near_end, "near-end"))
        await client.until_state("near-end")
        deadline = time.monotonic() + 10
        while not any(s[0] == ENDED for s in client.states):
            assert time.monotonic() < deadline, f"no Ended state: {client.states}"
            await client.collect(0.1)
        assert [m[1] for m in client.messages] == [near_end + k * PERIOD_NS for k in range(20)]
        ended = next(s for s in client.states if s[0] == ENDED)
        assert ended[1] == T0 + (N - 1) * PERIOD_NS and ended[4] == "", ended

        client.messages.clear()
        await ws.send(control(PLAY, 1.0, None, "again"))
        status, _, _, did_seek, _ = await client.until_state("again")
        assert (status, did_seek) == (PLAYING, True), "play at the end starts from the start"
        await client.collect(0.5)
        assert client.messages and client.messages[0][1] == T0
