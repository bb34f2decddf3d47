"""A bounded in-memory ring of the last N seconds of serialized messages (the fault snapshot's).

Entries are the messages as they go into a bag (CDR bytes, the topic, log and publish time),
so the ring's memory is bytes that can be counted: each entry costs its payload plus a fixed
:data:`ENTRY_OVERHEAD` (the entry tuple, its integers, the bytes object's header and the
deque slot). The ring holds what arrived within ``duration_s`` of log time before its newest
entry; an older entry is dropped as a newer one arrives, so the memory is bounded by the
duration times the message rate times the message size. Not thread-safe: the owner
(``record/snapshot.py``) holds a lock around every call.
"""

from __future__ import annotations

import sys
from collections import deque
from dataclasses import dataclass

#: bytes one entry costs beside its payload (CPython 3.12, 64 bit): the 4-tuple, two
#: nanosecond integers, the bytes object's header and the deque's slot pointer
ENTRY_OVERHEAD = (sys.getsizeof((0, 0, 0, b"")) + 2 * sys.getsizeof(2**62)
                  + sys.getsizeof(b"") + 8)


@dataclass(frozen=True)
class RingEntry:
    """One message as it goes into a bag."""

    topic: str
    log_time_ns: int
    publish_time_ns: int
    data: bytes


class MessageRing:
    """The last ``duration_s`` seconds (log time) of messages, oldest first.

    :raises ValueError: ``duration_s`` not > 0
    """

    def __init__(self, duration_s: float) -> None:
        if not duration_s > 0:
            raise ValueError(f"ring duration {duration_s}: must be > 0 s")
        self.duration_ns = int(duration_s * 1e9)
        #: topic names by index (an entry keeps the index, not a string per message)
        self._topics: list[str] = []
        self._topic_index: dict[str, int] = {}
        self._entries: deque[tuple[int, int, int, bytes]] = deque()
        self._payload = 0
        self._newest = 0
        #: entries dropped for age since the ring was made
        self.dropped = 0

    def append(self, topic: str, log_time_ns: int, publish_time_ns: int, data: bytes) -> None:
        """Add one message; drop what is older than the duration before the newest entry.

        :param topic: the message's topic
        :param log_time_ns: when it was received (ns)
        :param publish_time_ns: when it was sent (ns)
        :param data: its CDR bytes
        """
        index = self._topic_index.get(topic)
        if index is None:
            index = self._topic_index[topic] = len(self._topics)
            self._topics.append(topic)
        entries = self._entries
        entries.append((index, log_time_ns, publish_time_ns, data))
        self._payload += len(data)
        self._newest = max(self._newest, log_time_ns)
        horizon = self._newest - self.duration_ns
        while entries and entries[0][1] < horizon:
            self._payload -= len(entries.popleft()[3])
            self.dropped += 1

    def entries(self) -> list[RingEntry]:
        """A copy of the ring, oldest first (the ring goes on filling)."""
        topics = self._topics
        return [RingEntry(topics[i], log, pub, data) for i, log, pub, data in self._entries]

    def raw(self) -> tuple[list[str], list[tuple[int, int, int, bytes]]]:
        """A copy of the ring as it is kept: (topic names, entries of (topic index, log time,
        publish time, data)); cheap enough for a publishing thread (no per-entry object)."""
        return list(self._topics), list(self._entries)

    def clear(self) -> None:
        """Drop every entry."""
        self._entries.clear()
        self._payload = 0
        self._newest = 0

    def __len__(self) -> int:
        return len(self._entries)

    @property
    def payload_bytes(self) -> int:
        """Bytes of serialized messages held."""
        return self._payload

    @property
    def memory_bytes(self) -> int:
        """Payload plus the fixed cost of every entry: what the ring holds in memory."""
        return self._payload + ENTRY_OVERHEAD * len(self._entries)

    @property
    def span_ns(self) -> int:
        """Log-time span from the oldest to the newest entry."""
        if not self._entries:
            return 0
        return self._entries[-1][1] - self._entries[0][1]
