"""Find the rclpy class of a recorded message type name.

Bags name types ``pkg/msg/Type`` (rosbag2) and schemas name dependencies ``pkg/Type``; both
resolve to the generated Python module ``pkg.msg``. A type that is not installed is a
:class:`RecordingError` naming the package, so replay can say what to source or build.
"""

from __future__ import annotations

import importlib

from ssi_bridge.exceptions import RecordingError


def message_class(type_name: str) -> type:
    """Import the rclpy message class of ``pkg/msg/Type`` or ``pkg/Type``.

    :param type_name: ``pkg/msg/Type`` or ``pkg/Type``
    :raises RecordingError: another form, or the type is not installed
    """
    parts = type_name.split("/")
    if len(parts) not in (2, 3) or not all(parts):
        raise RecordingError(f"message type {type_name!r}: expected 'pkg/msg/Type'")
    pkg, name = parts[0], parts[-1]
    try:
        module = importlib.import_module(f"{pkg}.msg")
        cls: type = getattr(module, name)
        return cls
    except (ImportError, AttributeError) as err:
        raise RecordingError(f"message type {type_name} is not installed (is the workspace "
                             f"providing {pkg} sourced?)") from err


def message_fields(cls: type) -> dict[str, str]:
    """Field name -> rosidl type name of a generated message class, in wire order.

    Raises:
        RecordingError: ``cls`` is not a generated rosidl message class.
    """
    fields = getattr(cls, "get_fields_and_field_types", None)
    if fields is None:
        raise RecordingError(f"{cls.__name__} is not a generated ROS message class")
    result: dict[str, str] = fields()
    return result
