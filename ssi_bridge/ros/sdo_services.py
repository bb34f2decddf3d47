"""``~/sdo_read`` and ``~/sdo_write``: any object of a station by index, subindex and type.

The handlers turn a request into a call of :class:`~ssi_bridge.core.sdo_access.ObjectAccess`
and its result or exception into the answer: the value in the field of its type
(``signed_value``, ``unsigned_value``, ``float_value``, ``string_value``), or ``success:
false`` with the SDO abort code and its CiA 301 meaning, or the reason of a refusal. They run
on the services' one worker (``ros/services.py``), are recorded as ``~/events`` like the
register services, and never raise.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from ssi_bridge.core.sdo_access import ObjectAccess, value_kind
from ssi_bridge.exceptions import SdoAbortError, SsiBridgeError

#: log_event(kind, joint, request, success, message) of the services
LogEvent = Callable[[str, str, str, bool, str], None]


def _describe(request: Any) -> str:
    """The request as the event's text."""
    who = f"node_id={request.node_id}" + (f" joint={request.joint[:40]!r}" if request.joint
                                          else "")
    return (f"{who} index=0x{request.index:04X} subindex={request.subindex} "
            f"data_type={request.data_type[:40] or 'EDS'}")


class SdoServices:
    """The two handlers.

    :param access: typed object access of the node's stations
    :param log_event: records the call on ``~/events`` (and the log)
    :param log_error: logs an unexpected exception (a handler still answers)
    """

    def __init__(self, access: ObjectAccess, log_event: LogEvent,
                 log_error: Callable[[str], None]) -> None:
        self.access = access
        self._log_event = log_event
        self._log_error = log_error

    def _run(self, kind: str, request: Any, response: Any, body: Callable[[], str],
             extra: Callable[[], str] = lambda: "") -> Any:
        """Run ``body``; fill success, message and the abort fields; record; never raise."""
        response.abort_code, response.abort_meaning = 0, ""
        try:
            response.success, response.message = True, body()
        except SdoAbortError as err:
            response.success, response.message = False, f"{kind}: {err}"
            response.abort_code, response.abort_meaning = int(err.code), err.meaning
        except (SsiBridgeError, ValueError) as err:
            response.success, response.message = False, f"{kind}: {err}"
        except Exception as err:  # noqa: BLE001 - a service must answer, whatever happened
            self._log_error(f"{kind}: unexpected {type(err).__name__}: {err}")
            response.success = False
            response.message = f"{kind}: internal error {type(err).__name__}: {err}"
        who = request.joint or (f"node {request.node_id}" if request.node_id else "")
        self._log_event(kind, who, _describe(request) + extra(), response.success,
                        response.message)
        return response

    def read(self, request: Any, response: Any) -> Any:
        """~/sdo_read: upload one object and decode it by type."""
        def body() -> str:
            dtype, value, text = self.access.read(request.node_id, request.joint, request.index,
                                                  request.subindex, request.data_type)
            response.data_type = dtype.name
            setattr(response, f"{value_kind(dtype)}_value", value)
            return text
        return self._run("sdo_read", request, response, body)

    def write(self, request: Any, response: Any) -> Any:
        """~/sdo_write: encode the value of the type's field and download it."""
        chosen: list[str] = []

        def value_of(dtype: Any) -> Any:
            value = getattr(request, f"{value_kind(dtype)}_value")
            chosen.append(f" value={value!r}"[:80])
            return value

        def body() -> str:
            dtype, text = self.access.write(request.node_id, request.joint, request.index,
                                            request.subindex, request.data_type, value_of)
            response.data_type = dtype.name
            return text
        return self._run("sdo_write", request, response, body, lambda: "".join(chosen))


__all__ = ["SdoServices"]
