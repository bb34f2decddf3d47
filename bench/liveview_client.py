"""WebSocket client process of the live view case (node_liveview.py): one Foxglove client.

Usage: ``python bench/liveview_client.py URL TOPIC[,TOPIC...] READY_FILE OUT_FILE``

Speaks the Foxglove WebSocket protocol (serverInfo / advertise / subscribe, binary message
data with opcode 0x01) and subscribes to the given topics as Foxglove does for the panels
that show them. It only counts the messages (no decoding: the cost measured is the node's).
On the first message it writes READY_FILE; on SIGINT/SIGTERM it writes OUT_FILE as
"<messages> <first receive ns> <last receive ns>" and exits 0.
"""

from __future__ import annotations

import asyncio
import json
import os
import signal
import sys
import time

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
OP_MESSAGE_DATA = 0x01


async def stream(url: str, topics: list[str], ready: str, counts: list[int]) -> None:
    import websockets

    async with websockets.connect(url, subprotocols=SUBPROTOCOLS, max_size=None,
                                  close_timeout=1.0) as ws:
        channels: dict[str, int] = {}
        while not all(t in channels for t in topics):
            msg = json.loads(await ws.recv())
            if msg["op"] == "advertise":
                channels.update({c["topic"]: c["id"] for c in msg["channels"]})
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": i, "channelId": channels[t]} for i, t in enumerate(topics, start=1)]}))
        async for frame in ws:
            if isinstance(frame, bytes) and frame[0] == OP_MESSAGE_DATA:
                now = time.time_ns()
                if counts[0] == 0:
                    counts[1] = now
                    with open(ready + ".tmp", "w") as f:
                        f.write(str(now))
                    os.replace(ready + ".tmp", ready)
                counts[0] += 1
                counts[2] = now


def main(argv: list[str]) -> int:
    url, topics, ready, out = argv[1], argv[2].split(","), argv[3], argv[4]
    counts = [0, 0, 0]
    loop = asyncio.new_event_loop()
    task = loop.create_task(stream(url, topics, ready, counts))

    def stop() -> None:
        # the figures first: closing the connection may take a while under load
        with open(out + ".tmp", "w") as f:
            f.write(f"{counts[0]} {counts[1]} {counts[2]}\n")
        os.replace(out + ".tmp", out)
        task.cancel()

    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop)
    try:
        loop.run_until_complete(task)
    except asyncio.CancelledError:
        pass
    finally:
        loop.close()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
