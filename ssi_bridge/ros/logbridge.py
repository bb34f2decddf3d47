"""Route the Python ``logging`` records of the core stages and libraries to the ROS logger.

The stages left of the node log with the standard library (STYLE.md), and so do canopen and
python-can; inside the node those records appear like every other ROS log line (console
format, /rosout, log file) under a child of the node's logger named after the module:
``ssi_bridge.sim.supervisor.station`` logs as ``[ssi_bridge.sim.supervisor.station]``, ``canopen.emcy`` as
``[ssi_bridge.canopen.emcy]`` (with a namespace: ``[ns.ssi_bridge.…]``), never as a name in
brackets inside the message. canopen and python-can report protocol chatter at INFO (every
EMCY, NMT change); they are passed from WARNING up unless the node's logger is set to DEBUG.
Every message is cut to :data:`MAX_MESSAGE` characters: a value echoed from the
configuration (a 1 MB joint name) must not flood the log.
"""

from __future__ import annotations

import logging

from rclpy.logging import LoggingSeverity

from ssi_bridge.ros.rclpy_compat import RcutilsLogger

#: Python loggers bridged: this package and the CAN libraries it drives
BRIDGED = ("ssi_bridge", "canopen", "can")
#: libraries whose INFO is protocol chatter: bridged from WARNING unless the node logs DEBUG
CHATTY = ("canopen", "can")
#: longest message passed on; the rest is replaced by its length
MAX_MESSAGE = 1000


def clip(text: str, limit: int = MAX_MESSAGE) -> str:
    """``text`` cut to ``limit`` characters, saying how long it was."""
    if len(text) <= limit:
        return text
    return f"{text[:limit]}... ({len(text)} characters)"


class RosLogHandler(logging.Handler):
    """A logging handler that forwards records to child loggers of an rclpy logger."""

    def __init__(self, ros_logger: RcutilsLogger) -> None:
        super().__init__()
        self._ros = ros_logger
        self._children: dict[str, RcutilsLogger] = {}

    def child(self, name: str) -> RcutilsLogger:
        """The ROS logger of the Python logger ``name`` (``ssi_bridge.`` prefix dropped)."""
        logger = self._children.get(name)
        if logger is None:
            suffix = name[len("ssi_bridge."):] if name.startswith("ssi_bridge.") else name
            logger = self._ros if suffix == "ssi_bridge" else self._ros.get_child(suffix)
            self._children[name] = logger
        return logger

    def emit(self, record: logging.LogRecord) -> None:
        try:
            text = clip(record.getMessage())
            ros = self.child(record.name)
            if record.levelno >= logging.ERROR:
                ros.error(text)
            elif record.levelno >= logging.WARNING:
                ros.warning(text)
            elif record.levelno >= logging.INFO:
                ros.info(text)
            else:
                ros.debug(text)
        except Exception:  # noqa: BLE001 - logging must never break the caller
            self.handleError(record)


def _python_level(ros_logger: RcutilsLogger) -> int:
    """The Python level matching the ROS logger's effective severity."""
    severity = ros_logger.get_effective_level()
    if severity <= LoggingSeverity.DEBUG:
        return logging.DEBUG
    if severity <= LoggingSeverity.INFO:
        return logging.INFO
    if severity <= LoggingSeverity.WARN:
        return logging.WARNING
    return logging.ERROR


def install(ros_logger: RcutilsLogger, level: int | None = None) -> RosLogHandler:
    """Attach the handler to the bridged loggers (idempotent per process).

    ``level`` defaults to the ROS logger's effective level (``--log-level``).
    """
    uninstall()
    handler = RosLogHandler(ros_logger)
    level = _python_level(ros_logger) if level is None else level
    for name in BRIDGED:
        logger = logging.getLogger(name)
        logger.addHandler(handler)
        logger.setLevel(max(level, logging.WARNING) if name in CHATTY and level > logging.DEBUG
                        else level)
        logger.propagate = False
    return handler


def uninstall() -> None:
    """Detach the handler (before the ROS context goes away) and log to stderr again."""
    for name in BRIDGED:
        logger = logging.getLogger(name)
        for handler in list(logger.handlers):
            if isinstance(handler, RosLogHandler):
                logger.removeHandler(handler)
        logger.propagate = True
