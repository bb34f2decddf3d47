"""Route the core stages' ``logging`` records to the ROS logger of the node.

The stages left of the node log with the standard library (STYLE.md); inside the node those
records should appear like every other ROS log line (and reach /rosout), not as bare text.
"""

from __future__ import annotations

import logging

from rclpy.impl.rcutils_logger import RcutilsLogger


class RosLogHandler(logging.Handler):
    """A logging handler that forwards records to an rclpy logger at the same severity."""

    def __init__(self, ros_logger: RcutilsLogger) -> None:
        super().__init__()
        self._ros = ros_logger

    def emit(self, record: logging.LogRecord) -> None:
        try:
            text = f"[{record.name}] {record.getMessage()}"
            if record.levelno >= logging.ERROR:
                self._ros.error(text)
            elif record.levelno >= logging.WARNING:
                self._ros.warning(text)
            elif record.levelno >= logging.INFO:
                self._ros.info(text)
            else:
                self._ros.debug(text)
        except Exception:  # noqa: BLE001 - logging must never break the caller
            self.handleError(record)


def install(ros_logger: RcutilsLogger, level: int = logging.INFO) -> RosLogHandler:
    """Attach the handler to the ``ssi_bridge`` package logger (idempotent per process)."""
    root = logging.getLogger("ssi_bridge")
    for handler in list(root.handlers):
        if isinstance(handler, RosLogHandler):
            root.removeHandler(handler)
    handler = RosLogHandler(ros_logger)
    root.addHandler(handler)
    root.setLevel(level)
    root.propagate = False
    return handler


def uninstall() -> None:
    """Detach the handler (before the ROS context goes away) and log to stderr again."""
    root = logging.getLogger("ssi_bridge")
    for handler in list(root.handlers):
        if isinstance(handler, RosLogHandler):
            root.removeHandler(handler)
    root.propagate = True
