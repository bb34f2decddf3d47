"""A python-can interface a test can unplug and plug back (test helper, not a test module).

:class:`UnpluggableBus` is ssi_bridge's CAN-over-UDP bus (``base/udp_bus.py``) whose calls
fail the way python-can's socketcan interface fails on a lost network device while the file
named by the environment variable :data:`FLAG_ENV` exists: ``send`` and ``recv`` raise
``can.CanOperationError`` with ``error_code`` ENETDOWN ("Network is down", what socketcan
raises after ``ip link set can0 down``), and opening it raises ``OSError(ENODEV)`` (a USB
adapter pulled out: the network device is gone). A test registers it through python-can's
public interface registry, the ``can.interface`` entry point group, by putting a small
``*.dist-info`` with that entry point and this module on the node's PYTHONPATH
(``test_node_lost_interface.py``), so the node opens it as ``bus.interface:
ssi_test_unpluggable`` like any installed python-can plugin.
"""

from __future__ import annotations

import errno
import os
from typing import Any

import can

from ssi_bridge.base.udp_bus import open_udp_bus

#: the environment variable naming the flag file: the interface is unplugged while it exists
FLAG_ENV = "SSI_TEST_UNPLUGGED_FLAG"
#: the interface name the entry point registers
INTERFACE = "ssi_test_unpluggable"


def unplugged() -> bool:
    """True while the flag file exists."""
    path = os.environ.get(FLAG_ENV, "")
    return bool(path) and os.path.exists(path)


class UnpluggableBus(can.BusABC):
    """The CAN-over-UDP bus on ``channel``, failing as a lost socketcan device while unplugged."""

    def __init__(self, channel: Any = None, **kwargs: Any) -> None:
        if unplugged():
            raise OSError(errno.ENODEV, os.strerror(errno.ENODEV), str(channel))
        self._inner = open_udp_bus(str(channel))
        super().__init__(channel=channel)
        self.channel_info = f"unpluggable {self._inner.channel_info}"

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if unplugged():
            raise can.CanOperationError("Failed to transmit: Network is down", errno.ENETDOWN)
        self._inner.send(msg, timeout)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if unplugged():
            raise can.CanOperationError("Error receiving: Network is down", errno.ENETDOWN)
        return self._inner.recv(timeout), True

    def shutdown(self) -> None:
        super().shutdown()
        self._inner.shutdown()
