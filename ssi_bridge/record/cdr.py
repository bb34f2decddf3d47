"""Serialize rclpy messages to exact, clean little-endian CDR (XCDR1) for bag files.

Why not ``rclpy.serialization.serialize_message``: on these wheels it returns the DDS payload
with unzeroed alignment padding and up to 4 trailing bytes, which strict readers (rosbags)
reject as a size mismatch. Why not ``mcap_ros2``'s dynamic encoder: it refuses the numpy
arrays rclpy uses for fixed-size arrays, and is slower (docs/recording.md "Benchmark").

This module compiles, once per message class, a Python function from the class's rosidl
introspection (``get_fields_and_field_types()``). Runs of consecutive fixed-size fields are
packed with one precompiled :class:`struct.Struct` per possible start offset modulo 8, so the
CDR alignment rule (a primitive of size n starts at an offset that is a multiple of n,
counted from the end of the 4-byte encapsulation header) costs one table lookup per run.
"""

from __future__ import annotations

import re
import struct
import threading
from typing import Any, Callable

from ssi_bridge.record.types import message_class, message_fields

#: CDR encapsulation header: representation id CDR_LE (0x0001), options 0
CDR_LE_HEADER = b"\x00\x01\x00\x00"

#: rosidl primitive type -> (struct code, size in bytes)
PRIMITIVES: dict[str, tuple[str, int]] = {
    "boolean": ("?", 1), "octet": ("c", 1), "byte": ("c", 1), "char": ("B", 1),
    "uint8": ("B", 1), "int8": ("b", 1), "uint16": ("H", 2), "int16": ("h", 2),
    "uint32": ("I", 4), "int32": ("i", 4), "uint64": ("Q", 8), "int64": ("q", 8),
    "float": ("f", 4), "float32": ("f", 4), "double": ("d", 8), "float64": ("d", 8),
}

_SEQ = re.compile(r"^sequence<(?P<elem>[^,>]+)(?:, *\d+)?>$")
_ARRAY = re.compile(r"^(?P<elem>[^\[]+)\[(?P<n>\d+)\]$")
_STRING = re.compile(r"^w?string(?:<=\d+)?$")

Encoder = Callable[[object, bytearray], None]


def _run_structs(items: list[tuple[str, int, int]]) -> list[struct.Struct]:
    """Structs packing a run of (code, size, count) items for each start offset mod 8."""
    table = []
    for start in range(8):
        fmt, offset = "<", start
        for code, size, count in items:
            pad = -offset % size
            fmt += "x" * pad + f"{count}{code}" if count != 1 else "x" * pad + code
            offset += pad + size * count
        table.append(struct.Struct(fmt))
    return table


class _Compiler:
    """Generate the source of one encoder function per message class (recursive)."""

    def __init__(self) -> None:
        self.namespace: dict[str, Any] = {"_U32": _run_structs([("I", 4, 1)])}
        self.names: dict[type, str] = {}

    def compile(self, cls: type) -> str:
        """Return the name of the generated function encoding ``cls``, compiling it first."""
        if cls in self.names:
            return self.names[cls]
        fname = f"_enc_{cls.__module__.replace('.', '_')}_{cls.__name__}"
        self.names[cls] = fname
        lines = [f"def {fname}(m, b):"]
        run: list[tuple[str, int, int]] = []
        run_values: list[str] = []

        def close_run() -> None:
            if run:
                key = f"_R{len(self.namespace)}"
                self.namespace[key] = _run_structs(list(run))
                lines.append(f"    b += {key}[len(b) & 7].pack({', '.join(run_values)})")
                run.clear()
                run_values.clear()

        for field, ftype in message_fields(cls).items():
            attr = f"m.{field}"
            if ftype in PRIMITIVES:
                code, size = PRIMITIVES[ftype]
                run.append((code, size, 1))
                run_values.append(attr)
                continue
            array = _ARRAY.match(ftype)
            if array and array["elem"] in PRIMITIVES:
                code, size = PRIMITIVES[array["elem"]]
                run.append((code, size, int(array["n"])))
                run_values.append(f"*{attr}")
                continue
            close_run()
            lines.extend(self._dynamic_field(attr, ftype))
        close_run()
        if len(lines) == 1:
            lines.append("    pass")
        exec("\n".join(lines), self.namespace)  # noqa: S102 - source generated above
        return fname

    def _element(self, value: str, elem: str, indent: str) -> list[str]:
        """Source lines encoding one non-primitive element (string or nested message)."""
        if _STRING.match(elem):
            if elem.startswith("w"):
                raise NotImplementedError("wstring fields are not supported by the bag writer")
            return [f"{indent}_s = {value}.encode()",
                    f"{indent}b += _U32[len(b) & 7].pack(len(_s) + 1)",
                    f"{indent}b += _s",
                    f"{indent}b.append(0)"]
        return [f"{indent}{self.compile(message_class(elem))}({value}, b)"]

    def _dynamic_field(self, attr: str, ftype: str) -> list[str]:
        """Source lines for a field whose size is only known at run time."""
        seq = _SEQ.match(ftype)
        array = _ARRAY.match(ftype)
        if seq:
            elem = seq["elem"].strip()
            lines = [f"    b += _U32[len(b) & 7].pack(len({attr}))"]
            if elem in PRIMITIVES:
                code, size = PRIMITIVES[elem]
                if elem in ("octet", "byte"):
                    self.namespace["_octets"] = _octets
                    return lines + [f"    b += _octets({attr})"]
                lines += [f"    if {attr}:",
                          f"        b += bytes(-len(b) % {size})",
                          f"        b += struct.pack('<%d{code}' % len({attr}), *{attr})"]
                self.namespace["struct"] = struct
                return lines
            lines.append(f"    for _e in {attr}:")
            return lines + self._element("_e", elem, "        ")
        if array:
            return [f"    for _e in {attr}:"] + self._element("_e", array["elem"], "        ")
        return self._element(attr, ftype, "    ")


def _octets(value: Any) -> bytes:
    """Bytes of an octet sequence, which rclpy holds as a list of 1-byte ``bytes``."""
    if value and isinstance(value[0], bytes):
        return b"".join(value)
    return bytes(value)


_lock = threading.Lock()
_compiler = _Compiler()
_cache: dict[type, Encoder] = {}


def encoder_for(cls: type) -> Encoder:
    """Return the compiled body encoder of a message class (thread-safe, cached).

    :param cls: a generated rclpy message class
    :raises RecordingError: a field type of the class is not installed
    """
    try:
        return _cache[cls]
    except KeyError:
        with _lock:
            fname = _compiler.compile(cls)
            _cache[cls] = _compiler.namespace[fname]
            return _cache[cls]


def serialize(msg: object) -> bytes:
    """Serialize an rclpy message to CDR bytes: header, exact body, zeroed padding.

    :param msg: an rclpy message
    """
    body = bytearray()
    encoder_for(type(msg))(msg, body)
    return CDR_LE_HEADER + bytes(body)
