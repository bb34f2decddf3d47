"""The error frames a master's CAN controller reports, put on the simulated wire (faults).

On a real bus, bus-off and error passive are states of each node's own CAN controller, which
SocketCAN reports to the application as error frames (``protocol/can_errors.py``); they are
never frames on the wire. The simulated wire has no controller of the master's to go bus-off,
so the faults BUS_OFF and ERROR_PASSIVE hand the master the frames its controller would
report, in the order a controller climbing the error counter reports them (ISO 11898-1 fault
confinement: warning at 96, passive at 128, bus-off above 255):

* BUS_OFF on: CRTL TX warning (counter 96), CRTL TX passive (128), BUSOFF; off: RESTARTED
  (the controller restarted, counters 0);
* ERROR_PASSIVE on: CRTL TX warning (96), CRTL TX passive (128); off: CRTL back to error
  active (counters 0).

Each carries CAN_ERR_CNT with the TX / RX error counters in data[6] / data[7]. They go out
through :meth:`~ssi_bridge.sim.gateway.bus.LossyBus.report`, past the station's mute.
"""

from __future__ import annotations

import can

from ssi_bridge.protocol.can_errors import (
    CAN_ERR_BUSOFF, CAN_ERR_CNT, CAN_ERR_CRTL, CAN_ERR_CRTL_ACTIVE, CAN_ERR_CRTL_TX_PASSIVE,
    CAN_ERR_CRTL_TX_WARNING, CAN_ERR_DLC, CAN_ERR_RESTARTED,
)


def error_frame(mask: int, crtl: int = 0, tx: int = 0, rx: int = 0) -> can.Message:
    """A SocketCAN error frame as python-can delivers it: ``is_error_frame``, the class
    ``mask`` as identifier, 8 data bytes (controller status in data[1], counters in 6/7).

    :param crtl: the controller status byte (data[1])
    :param tx: the transmit error counter (data[6])
    :param rx: the receive error counter (data[7])
    """
    data = bytearray(CAN_ERR_DLC)
    data[1], data[6], data[7] = crtl, tx, rx
    return can.Message(arbitration_id=mask, is_extended_id=False, is_error_frame=True,
                       data=data)


def error_frames(*, bus_off: bool, on: bool) -> list[can.Message]:
    """The frames of the fault BUS_OFF (``bus_off``) or ERROR_PASSIVE going ``on`` or off."""
    counted = CAN_ERR_CRTL | CAN_ERR_CNT
    if on:
        frames = [error_frame(counted, CAN_ERR_CRTL_TX_WARNING, tx=96),
                  error_frame(counted, CAN_ERR_CRTL_TX_PASSIVE, tx=128)]
        if bus_off:
            frames.append(error_frame(CAN_ERR_BUSOFF | CAN_ERR_CNT, tx=255))
        return frames
    if bus_off:
        return [error_frame(CAN_ERR_RESTARTED | CAN_ERR_CNT)]
    return [error_frame(counted, CAN_ERR_CRTL_ACTIVE)]


def report_error_frames(bus: can.BusABC, *, bus_off: bool, on: bool) -> None:
    """Put the frames of :func:`error_frames` on ``bus`` (a LossyBus: past its mute).

    :param bus_off: the BUS_OFF set of frames, else ERROR_PASSIVE
    :param on: the condition begins (True) or ends (False)
    """
    send = getattr(bus, "report", bus.send)
    for msg in error_frames(bus_off=bus_off, on=on):
        send(msg)


__all__ = ["error_frame", "error_frames", "report_error_frames"]
