"""SDO abort codes of CiA 301 (Table 22 of CiA 301 v4.2), as named constants with their text.

The gateway raises them at the SDO boundary (canopen's ``SdoServer`` turns an
``SdoAbortedError`` into the abort frame); the client turns a received code back into an
:class:`~ssi_bridge.exceptions.SdoAbortError` whose message carries the CiA 301 meaning.
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


_MEANING: dict[int, str] = {
    SdoAbort.TOGGLE_NOT_ALTERNATED: "toggle bit not alternated",
    SdoAbort.TIMEOUT: "SDO protocol timed out",
    SdoAbort.INVALID_COMMAND: "client/server command specifier not valid or unknown",
    SdoAbort.INVALID_BLOCK_SIZE: "invalid block size",
    SdoAbort.INVALID_SEQUENCE: "invalid sequence number",
    SdoAbort.CRC_ERROR: "CRC error",
    SdoAbort.OUT_OF_MEMORY: "out of memory",
    SdoAbort.UNSUPPORTED_ACCESS: "unsupported access to an object",
    SdoAbort.WRITE_ONLY: "attempt to read a write only object",
    SdoAbort.READ_ONLY: "attempt to write a read only object",
    SdoAbort.NO_SUCH_OBJECT: "object does not exist in the object dictionary",
    SdoAbort.NOT_MAPPABLE: "object cannot be mapped to the PDO",
    SdoAbort.PDO_TOO_LONG: "the number and length of the objects to be mapped "
                           "would exceed PDO length",
    SdoAbort.INCOMPATIBLE_PARAMETER: "general parameter incompatibility reason",
    SdoAbort.INCOMPATIBLE_DEVICE: "general internal incompatibility in the device",
    SdoAbort.HARDWARE_ERROR: "access failed due to a hardware error",
    SdoAbort.LENGTH_MISMATCH: "data type does not match, length of service parameter "
                              "does not match",
    SdoAbort.LENGTH_TOO_HIGH: "data type does not match, length of service parameter too high",
    SdoAbort.LENGTH_TOO_LOW: "data type does not match, length of service parameter too low",
    SdoAbort.NO_SUCH_SUBINDEX: "sub-index does not exist",
    SdoAbort.INVALID_VALUE: "invalid value for parameter (download only)",
    SdoAbort.VALUE_TOO_HIGH: "value of parameter written too high (download only)",
    SdoAbort.VALUE_TOO_LOW: "value of parameter written too low (download only)",
    SdoAbort.MAX_BELOW_MIN: "maximum value is less than minimum value",
    SdoAbort.RESOURCE_UNAVAILABLE: "resource not available: SDO connection",
    SdoAbort.GENERAL_ERROR: "general error",
    SdoAbort.CANNOT_STORE: "data cannot be transferred or stored to the application",
    SdoAbort.CANNOT_STORE_LOCAL: "data cannot be transferred or stored to the application "
                                 "because of local control",
    SdoAbort.CANNOT_STORE_STATE: "data cannot be transferred or stored to the application "
                                 "because of the present device state",
    SdoAbort.NO_DATA: "no data available",
}


def describe_abort(code: int) -> str:
    """Return the CiA 301 text for ``code`` (or say that the code is not a CiA 301 code)."""
    try:
        return _MEANING[code]
    except KeyError:
        return f"abort code 0x{code:08X} is not defined by CiA 301 (manufacturer specific?)"
