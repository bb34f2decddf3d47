"""The bridge's one time base: CAN wire time, and its one conversion to ROS time.

Every instant in the data path is a *wire time*: seconds of CLOCK_REALTIME as a float, the
base python-can gives every received frame (``can.Message.timestamp``: ``time.time()`` on the
``virtual`` interface, the kernel receive time on ``socketcan`` and ``udp_multicast``). SYNC
send time, latch time, TPDO arrival, ``header.stamp``, recorded and CAN-log times are all
wire times, so no instant is ever moved from one clock into another by reading two clocks
(a thread switch between two reads shifts the result by the switch, up to Python's 5 ms GIL
switch interval). The same base holds in every process and, with NTP, on every host.

* :func:`wire_now` reads the clock (one read).
* :func:`frame_wire_time` is the instant a received frame was on the wire: its timestamp,
  except on ``udp_multicast`` between processes, where the receive time is as late as the
  sending process woke up (milliseconds under CPU load) and the frame carries its sender's
  end-of-frame wire time instead (``base/udp_bus.py``). A station latches at the SYNC's
  wire time, whatever its receive time.
* :func:`to_ros_ns` is the conversion to ROS time: ROS system time *is* CLOCK_REALTIME, so it
  is the identity in nanoseconds. (With ``use_sim_time`` the node adds one offset it takes
  from the ``/clock`` message itself, see ``ros/stamps.py``.)
* :class:`ModelClock` is a simulated station's clock: wire time minus the station's start
  instant (a constant), so the encoder motion and the latch share the base in small floats.

NTP: a *slewed* clock keeps every difference; a *step* moves wire time as it moves ROS time.
The node keeps ``header.stamp`` strictly increasing across a backward step and counts it.
"""

from __future__ import annotations

import logging
import time

import can
from canopen.network import MessageListener

logger = logging.getLogger(__name__)

#: the wire clock (CLOCK_REALTIME, s); python-can stamps frames in this base
wire_now = time.time


def frame_wire_time(msg: can.Message) -> float:
    """The wire time (s) of a received frame ``msg``: its sender's end of frame when the frame
    carries one (``wire_time``, udp_multicast), else its timestamp (0.0: none)."""
    wire = getattr(msg, "wire_time", 0.0)
    return wire if wire else msg.timestamp


def to_ros_ns(t: float) -> int:
    """ROS system time (ns) of wire time ``t`` (s): the same clock, only the unit changes."""
    return round(t * 1e9)


class ModelClock:
    """A simulated station's time: seconds of wire time since ``epoch`` (its start)."""

    def __init__(self, epoch: float | None = None) -> None:
        #: wire time (s) at which the model's time is 0
        self.epoch = wire_now() if epoch is None else epoch

    def __call__(self) -> float:
        """The model time now."""
        return wire_now() - self.epoch

    def at(self, wire_t: float) -> float:
        """The model time of wire time ``wire_t`` (a frame's timestamp)."""
        return wire_t - self.epoch


class WireTimeListener(MessageListener):
    """canopen's network listener, handing subscribers each frame's wire time.

    canopen passes ``msg.timestamp`` on: on udp_multicast the receive time, late by however
    long the sending process slept past the frame's end. This passes
    :func:`frame_wire_time` instead (the same value on every
    other interface), so a station latches on the instant its SYNC was on the wire.
    """

    def on_message_received(self, msg: can.Message) -> None:
        """Dispatch ``msg`` to the network's subscribers with its wire time."""
        if msg.is_error_frame or msg.is_remote_frame:
            return
        try:
            self.network.notify(msg.arbitration_id, msg.data, frame_wire_time(msg))
        except Exception as err:  # noqa: BLE001 - as canopen's: a callback must not stop it
            logger.error("%s", err)


__all__ = ["ModelClock", "WireTimeListener", "frame_wire_time", "to_ros_ns", "wire_now"]
