"""Every use of canopen's private API in one place (canopen 2.4), checked by a canary.

* :func:`subscribers`: the callbacks ``Network.subscribe`` registered for a COB-ID
  (``Network.subscribers``): the guarded listener calls each on its own, and the master takes
  canopen's own PDO handlers off the COB-IDs it routes itself;
* :func:`pdo_handler`: the handler a ``PdoMap`` subscribes when it is saved
  (``PdoMap.on_message``).

``test/gateway/test_library_compat.py`` fails on a canopen whose private names changed.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import canopen


def subscribers(network: canopen.Network, can_id: int) -> list[Callable[..., Any]]:
    """The callbacks subscribed to ``can_id`` (the network's own list: do not change it)."""
    return network.subscribers.get(can_id, [])


def pdo_handler(node: canopen.RemoteNode, tpdo: int) -> Callable[..., Any]:
    """The handler TPDO ``tpdo`` of ``node`` subscribes to its COB-ID when saved."""
    return node.tpdo[tpdo].on_message


__all__ = ["pdo_handler", "subscribers"]
