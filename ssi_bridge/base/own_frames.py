"""A kernel socket filter that drops a UDP sender's own datagrams before the receive queue.

A CAN controller does not receive its own frames; a udp_multicast bus (``base/udp_bus.py``)
sends through one socket and receives through another, and multicast loop-back hands the
receive socket every frame the bus sent. :func:`drop_own_frames` attaches a classic BPF
program (Linux ``SO_ATTACH_FILTER``) to the receive socket that drops every datagram from the
send socket's address and port, so the receiving thread does not even wake up for them (the
master's own SYNC, every cycle). Where the system refuses the filter the bus drops them on
receipt, as before.
"""

from __future__ import annotations

import ctypes
import logging
import socket
import struct

logger = logging.getLogger(__name__)

#: Linux: attach a classic BPF program to a socket (asm-generic/socket.h)
SO_ATTACH_FILTER = 26
#: classic BPF (linux/filter.h): loads relative to the network (IP) header, the opcodes of
#: a 16- and a 32-bit absolute load, a jump if equal to a constant, a return of a constant
_SKF_NET_OFF = -0x100000
_LDH_ABS, _LD_ABS, _JEQ_K, _RET_K = 0x28, 0x20, 0x15, 0x06


def own_frames_filter(address: tuple[str, int]) -> list[tuple[int, int, int, int]]:
    """A classic BPF program (code, jt, jf, k per instruction) that drops every datagram
    from ``address`` (IPv4 address, UDP port) and accepts the others whole. A UDP socket's
    filter sees the datagram from its UDP header on: the source port at offset 0."""
    source = int.from_bytes(socket.inet_aton(address[0]), "big")
    return [(_LDH_ABS, 0, 0, 0),  # A = the UDP source port
            (_JEQ_K, 0, 3, address[1]),  # another port: accept
            (_LD_ABS, 0, 0, (_SKF_NET_OFF + 12) & 0xFFFFFFFF),  # A = the IPv4 source
            (_JEQ_K, 0, 1, source),  # another address: accept
            (_RET_K, 0, 0, 0),  # this bus's own frame: dropped
            (_RET_K, 0, 0, 0xFFFFFFFF)]  # accepted whole


def drop_own_frames(sock: socket.socket, address: tuple[str, int]) -> bool:
    """Have the kernel drop every datagram from ``address`` before ``sock`` queues it
    (:func:`own_frames_filter` as a socket filter, ``SO_ATTACH_FILTER``).

    :returns: True when the filter is attached; False where the system refuses it (the
        receive path then drops those datagrams itself)
    """
    program = own_frames_filter(address)
    code = ctypes.create_string_buffer(b"".join(struct.pack("@HBBI", *op) for op in program))
    # struct sock_fprog: the instruction count and a pointer to them (the kernel copies them)
    fprog = struct.pack("@HP", len(program), ctypes.addressof(code))
    try:
        sock.setsockopt(socket.SOL_SOCKET, SO_ATTACH_FILTER, fprog)
    except OSError as err:
        logger.debug("no socket filter for the own frames of %s: %s", address, err)
        return False
    return True


__all__ = ["SO_ATTACH_FILTER", "drop_own_frames", "own_frames_filter"]
