"""Exceptions of ssi_bridge: one base class, a subclass per failure a caller can act on.

::

    SsiBridgeError
     +-- ConfigError (ValueError)            a configuration value is out of range
     +-- RegisterError                       a module register access was refused
     |    +-- RegisterReadError               REG_RD_ABORT = 1 (reserved, write-only, > 63)
     |    +-- RegisterWriteError              REG_WR_ACCEPT = 0 (read-only, reserved, range)
     |         +-- ParameterError             REG_PARA1 set the module rejects (ERR_PARA)
     +-- StorageError (OSError)              retentive register storage failed
     +-- BusError                            the CAN / CANopen side failed
     |    +-- SdoAbortError                   the gateway answered with an SDO abort code
     |    +-- HandshakeTimeout (TimeoutError) a register handshake step did not complete
     |    +-- HandshakeRejected               the module refused the handshake
     |    +-- GatewayUnavailable              no heartbeat / no answer from the gateway
     +-- RecordingError                      a session could not be started or written

Messages carry the register address in hex and the reason, so a service response can pass
them to a person unchanged.
"""

from __future__ import annotations


class SsiBridgeError(Exception):
    """Base class of every error raised by ssi_bridge."""


class ConfigError(SsiBridgeError, ValueError):
    """A configuration value is invalid; the message names the field and the allowed range."""


class RegisterError(SsiBridgeError):
    """A module register access was refused.

    :param address: register address (0-63, or the out-of-range value requested)
    :param reason: short human-readable reason, e.g. ``"read-only"``
    """

    def __init__(self, address: int, reason: str, message: str | None = None) -> None:
        self.address = address
        self.reason = reason
        super().__init__(message or f"register 0x{address:02X} ({address}): {reason}")


class RegisterReadError(RegisterError):
    """The module answered a read with REG_RD_ABORT = 1."""


class RegisterWriteError(RegisterError):
    """The module answered a write with REG_WR_ACCEPT = 0."""


class ParameterError(RegisterWriteError):
    """A REG_PARA1 parameter set is invalid (the module would raise ERR_PARA)."""


class StorageError(SsiBridgeError, OSError):
    """Retentive register storage could not be read or written."""


class BusError(SsiBridgeError):
    """The CAN bus or the CANopen gateway failed."""


class SdoAbortError(BusError):
    """The gateway aborted an SDO transfer.

    :param code: CiA 301 abort code
    :param meaning: the text CiA 301 gives for the code
    """

    def __init__(self, code: int, meaning: str, message: str | None = None) -> None:
        self.code = code
        self.meaning = meaning
        super().__init__(message or f"SDO abort 0x{code:08X}: {meaning}")


class HandshakeTimeout(BusError, TimeoutError):
    """A step of the register handshake did not complete in time."""


class HandshakeRejected(BusError):
    """The module refused a register read or write in the handshake."""


class GatewayUnavailable(BusError):
    """The gateway is silent (no heartbeat, no SDO answer) or not operational."""


class RecordingError(SsiBridgeError):
    """A recording session could not be started, written or closed."""
