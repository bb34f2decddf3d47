"""SDO abort codes of CiA 301 (Table 22 of CiA 301 v4.2), as named constants.

The simulated gateway raises them at the SDO boundary (canopen's ``SdoServer`` turns an
``SdoAbortedError`` into the abort frame); the master turns a received code back into an
:class:`~ssi_bridge.exceptions.SdoAbortError` whose message carries the CiA 301 meaning as
canopen words it (``client/sdo.py``).
"""

from __future__ import annotations

from enum import IntEnum


class SdoAbort(IntEnum):
    """CiA 301 SDO abort codes."""

    TOGGLE_NOT_ALTERNATED = 0x05030000
    TIMEOUT = 0x05040000
    INVALID_COMMAND = 0x05040001
    INVALID_BLOCK_SIZE = 0x05040002
    INVALID_SEQUENCE = 0x05040003
    CRC_ERROR = 0x05040004
    OUT_OF_MEMORY = 0x05040005
    UNSUPPORTED_ACCESS = 0x06010000
    WRITE_ONLY = 0x06010001
    READ_ONLY = 0x06010002
    NO_SUCH_OBJECT = 0x06020000
    NOT_MAPPABLE = 0x06040041
    PDO_TOO_LONG = 0x06040042
    INCOMPATIBLE_PARAMETER = 0x06040043
    INCOMPATIBLE_DEVICE = 0x06040047
    HARDWARE_ERROR = 0x06060000
    LENGTH_MISMATCH = 0x06070010
    LENGTH_TOO_HIGH = 0x06070012
    LENGTH_TOO_LOW = 0x06070013
    NO_SUCH_SUBINDEX = 0x06090011
    INVALID_VALUE = 0x06090030
    VALUE_TOO_HIGH = 0x06090031
    VALUE_TOO_LOW = 0x06090032
    MAX_BELOW_MIN = 0x06090036
    RESOURCE_UNAVAILABLE = 0x060A0023
    GENERAL_ERROR = 0x08000000
    CANNOT_STORE = 0x08000020
    CANNOT_STORE_LOCAL = 0x08000021
    CANNOT_STORE_STATE = 0x08000022
    NO_DATA = 0x08000024


__all__ = ["SdoAbort"]
