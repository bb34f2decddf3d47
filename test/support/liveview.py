"""A client of the node's live view (the Foxglove WebSocket server, subprotocol
``foxglove.sdk.v1``) that calls its services and parameters as Foxglove's panels do, and a
free TCP port for the server."""

from __future__ import annotations

import asyncio
import json
import socket
import struct
import time
from dataclasses import dataclass, field
from typing import Any


def free_port() -> int:
    """A TCP port nothing listens on right now (the kernel's choice)."""
    with socket.socket() as s:
        s.bind(("0.0.0.0", 0))
        return int(s.getsockname()[1])


SUBPROTOCOLS = ["foxglove.sdk.v1"]
#: binary client op "Service Call Request" and server op "Service Call Response"
OP_SERVICE_CALL = 0x02
OP_SERVICE_RESPONSE = 0x03
CALL_HEADER = struct.Struct("<BIII")  # opcode, service id, call id, encoding length


@dataclass
class LiveViewClient:
    """One connection; every text message kept in order, service answers by call id."""

    ws: Any
    info: dict = field(default_factory=dict)
    services: dict[str, dict] = field(default_factory=dict)
    texts: list[dict] = field(default_factory=list)
    answers: dict[int, tuple[str, bytes]] = field(default_factory=dict)
    _next_call: int = 0

    async def pump(self, until: Any, timeout: float = 20.0) -> None:
        """Read messages until ``until()`` holds (TimeoutError after ``timeout`` s)."""
        deadline = time.monotonic() + timeout
        while not until():
            frame = await asyncio.wait_for(self.ws.recv(), max(0.01, deadline - time.monotonic()))
            if isinstance(frame, str):
                msg = json.loads(frame)
                self.texts.append(msg)
                if msg["op"] == "serverInfo":
                    self.info = msg
                elif msg["op"] == "advertiseServices":
                    self.services.update({s["name"]: s for s in msg["services"]})
                elif msg["op"] == "serviceCallFailure":
                    self.answers[msg["callId"]] = ("failure", msg["message"].encode())
            elif frame[0] == OP_SERVICE_RESPONSE:
                _, _sid, call_id, n = CALL_HEADER.unpack_from(frame)
                self.answers[call_id] = ("ok", frame[CALL_HEADER.size + n:])

    async def drain(self, seconds: float) -> None:
        """Read whatever arrives within ``seconds``."""
        try:
            await self.pump(lambda: False, seconds)
        except (asyncio.TimeoutError, TimeoutError):
            pass

    async def call_raw(self, name: str, payload: bytes) -> tuple[str, bytes]:
        """Send ``payload`` (cdr) to service ``name``; ("ok", response) or ("failure", text)."""
        self._next_call += 1
        call_id = self._next_call
        await self.ws.send(CALL_HEADER.pack(OP_SERVICE_CALL, self.services[name]["id"], call_id,
                                            3) + b"cdr" + payload)
        await self.pump(lambda: call_id in self.answers, 30.0)
        return self.answers[call_id]

    async def call(self, name: str, request: dict) -> Any:
        """Call service ``name`` with ``request`` (field -> value); the decoded response."""
        from mcap_ros2._dynamic import generate_dynamic, serialize_dynamic

        svc = self.services[name]
        req, res = svc["request"], svc["response"]
        payload = serialize_dynamic(req["schemaName"], req["schema"])[req["schemaName"]](request)
        kind, data = await self.call_raw(name, payload)
        assert kind == "ok", data.decode()
        return generate_dynamic(res["schemaName"], res["schema"])[res["schemaName"]](data)

    async def parameters(self, op: str, **fields: Any) -> list[dict]:
        """Send ``op`` with an id; the parameters of its ``parameterValues`` answer."""
        rid = f"{op}-{len(self.texts)}"
        await self.ws.send(json.dumps({"op": op, "id": rid, **fields}))
        await self.pump(lambda: any(m.get("id") == rid for m in self.texts))
        return next(m for m in self.texts if m.get("id") == rid)["parameters"]


async def _session(port: int, body: Any) -> Any:
    import websockets

    async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=SUBPROTOCOLS,
                                  open_timeout=20.0, max_size=None) as ws:
        client = LiveViewClient(ws)
        await client.pump(lambda: bool(client.info))
        if "services" in client.info["capabilities"]:
            await client.pump(lambda: bool(client.services))
        return await body(client)


def session(port: int, body: Any) -> Any:
    """Run ``async body(client)`` on a fresh connection to the live view on ``port``."""
    return asyncio.run(_session(port, body))
