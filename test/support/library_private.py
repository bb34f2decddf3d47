"""What python-can, canopen and rclpy keep private, read from their installed sources (for
test/support/private_access.py, the scanner of test/packaging/test_private_access.py).

Nothing is listed by hand:

* ``private``: every ``_name`` (not a dunder) the libraries' sources define or use as an
  attribute, a function, a method or a class;
* ``hooks``: the private methods whose docstring invites a subclass to override them
  (python-can's ``BusABC._recv_internal``, ``_send_periodic_internal``, ...);
* ``config``: the UPPER_CASE class attributes of the libraries' classes (canopen's
  ``Network.NOTIFIER_CYCLE``, ``SdoClient.RESPONSE_TIMEOUT``, ...);
* ``tables``: the containers a library object keeps its registrations in (an attribute its
  class's own methods change in place: ``Network.subscribers``, ``Network.nodes``,
  ``Notifier.listeners``, ``LocalNode.data_store``, ...);
* :func:`class_names`: per library class, the names of its own code (its MRO's sources and
  ``__dict__``); :class:`ProjectClasses`: which classes of the scanned package derive from
  library classes.
"""

from __future__ import annotations

import ast
import importlib
import inspect
import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path

#: the libraries whose private parts only their adapter may touch
LIBRARIES = ("can", "canopen", "rclpy")
#: the adapter modules (one per library): they may touch anything
ADAPTERS = ("ssi_bridge/base/can_compat.py", "ssi_bridge/base/canopen_compat.py",
            "ssi_bridge/ros/rclpy_compat.py")
#: library module path components that are implementation, not API (``rclpy.impl``)
INTERNAL_PARTS = ("impl",)
#: methods that change a container in place
MUTATORS = frozenset({"append", "extend", "insert", "remove", "pop", "clear", "update",
                      "setdefault", "add", "discard", "popitem", "sort", "reverse",
                      "__setitem__", "__delitem__"})


def is_container(value: ast.expr | None) -> bool:
    """A new list, dict or set."""
    if isinstance(value, (ast.List, ast.Dict, ast.Set, ast.ListComp, ast.DictComp,
                          ast.SetComp)):
        return True
    return (isinstance(value, ast.Call) and isinstance(value.func, ast.Name)
            and value.func.id in ("list", "dict", "set"))


def is_private(name: str) -> bool:
    """``_name``, not a dunder."""
    return name.startswith("_") and not name.startswith("__")


def is_config(name: str) -> bool:
    """An UPPER_CASE name (a class's setting)."""
    return len(name) > 1 and name.isupper() and not name.startswith("_")


def targets(node: ast.AST) -> list[ast.expr]:
    """What an assignment (plain, annotated, augmented) or a ``del`` writes to."""
    if isinstance(node, ast.Assign):
        return list(node.targets)
    if isinstance(node, (ast.AnnAssign, ast.AugAssign)):
        return [node.target]
    if isinstance(node, ast.Delete):
        return list(node.targets)
    return []


@dataclass(frozen=True)
class Facts:
    """What the installed libraries keep private (see the module docstring)."""

    private: frozenset[str]
    hooks: frozenset[str]
    config: frozenset[str]
    tables: frozenset[str]


def _library_sources() -> Iterator[tuple[str, ast.Module]]:
    for lib in LIBRARIES:
        root = Path(importlib.import_module(lib).__file__ or "").parent
        for path in sorted(root.rglob("*.py")):
            try:
                yield lib, ast.parse(path.read_text(encoding="utf-8"))
            except (SyntaxError, UnicodeDecodeError):  # pragma: no cover - vendored oddities
                continue


@cache
def library_facts() -> Facts:
    """The private names, override hooks, class constants and registries of the libraries."""
    private: set[str] = set()
    hooks: set[str] = set()
    config: set[str] = set()
    tables: set[str] = set()
    for _lib, tree in _library_sources():
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and is_private(node.attr):
                private.add(node.attr)
            elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                if is_private(node.name):
                    private.add(node.name)
                    doc = ast.get_docstring(node) or ""
                    if not isinstance(node, ast.ClassDef) and re.search(r"overrid|\bhook\b",
                                                                        doc, re.I):
                        hooks.add(node.name)
                if isinstance(node, ast.ClassDef):
                    for item in node.body:
                        for target in targets(item):
                            if isinstance(target, ast.Name) and is_config(target.id):
                                config.add(target.id)
            changed: ast.expr | None = None
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) \
                    and node.func.attr in MUTATORS:
                changed = node.func.value
            for target in targets(node):
                if isinstance(target, ast.Subscript):
                    changed = target.value
            while isinstance(changed, (ast.Call, ast.Subscript)):  # d.setdefault(k, {})[i] =
                changed = changed.func if isinstance(changed, ast.Call) else changed.value
                if isinstance(changed, ast.Attribute) and changed.attr in MUTATORS:
                    changed = changed.value
            if (isinstance(changed, ast.Attribute) and isinstance(changed.value, ast.Name)
                    and changed.value.id == "self" and not is_private(changed.attr)):
                tables.add(changed.attr)
    return Facts(frozenset(private), frozenset(hooks), frozenset(config), frozenset(tables))


@cache
def class_names(cls: type) -> frozenset[str]:
    """Every name the library code of ``cls`` and its bases defines or uses on ``self``/``cls``
    (attributes, methods, class attributes), private or not."""
    names: set[str] = set()
    for klass in cls.__mro__:
        if klass.__module__.split(".")[0] not in LIBRARIES:
            continue
        names.update(vars(klass))
        names.update(getattr(klass, "__slots__", ()))
        try:
            tree = ast.parse(inspect.cleandoc("\n" + inspect.getsource(klass)))
        except (OSError, TypeError, SyntaxError):
            continue  # a compiled class: its __dict__ is all there is
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) \
                    and node.value.id in ("self", "cls"):
                names.add(node.attr)
    return frozenset(names)


@dataclass
class ProjectClasses:
    """Classes of the scanned package by name -> the library classes they derive from
    (through project classes too); a class with none is the project's own."""

    bases: dict[str, list[ast.expr]] = field(default_factory=dict)
    bindings: dict[str, dict[str, str]] = field(default_factory=dict)

    def add_module(self, tree: ast.Module, binding: dict[str, str]) -> None:
        """Index the classes of one module (``binding``: its imports; call for every module
        before asking)."""
        for node in ast.walk(tree):
            if isinstance(node, ast.ClassDef):
                self.bases.setdefault(node.name, []).extend(node.bases)
                self.bindings.setdefault(node.name, {}).update(binding)

    def library_bases(self, bases: Iterable[ast.expr], binding: dict[str, str],
                      seen: frozenset[str] = frozenset()) -> list[type]:
        """The library classes among ``bases`` (expressions in a module with ``binding``)."""
        found: list[type] = []
        for base in bases:
            dotted = _dotted(base)
            if dotted is None:
                continue
            root, _, rest = dotted.partition(".")
            target = binding.get(root)
            obj = None if target is None else _resolve(f"{target}.{rest}" if rest else target)
            if isinstance(obj, type):  # imported (a re-export too): its real bases
                found.extend(k for k in obj.__mro__
                             if k.__module__.split(".")[0] in LIBRARIES)
            elif dotted in self.bases and dotted not in seen:
                found.extend(self.library_bases(self.bases[dotted], self.bindings[dotted],
                                                seen | {dotted}))
        return found


def _dotted(node: ast.expr) -> str | None:
    parts: list[str] = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    if isinstance(node, ast.Subscript):  # Generic[...] and the like
        return _dotted(node.value)
    if not isinstance(node, ast.Name):
        return None
    return ".".join([node.id, *reversed(parts)])


@cache
def _resolve(dotted: str) -> object:
    parts = dotted.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj: object = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        for name in parts[cut:]:
            obj = getattr(obj, name, None)
        return obj
    return None


def import_bindings(tree: ast.Module) -> dict[str, str]:
    """Local name -> the dotted name it was imported as, for every import of a module."""
    binding: dict[str, str] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.asname:
                    binding[alias.asname] = alias.name
                else:
                    root = alias.name.split(".")[0]
                    binding[root] = root
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            for alias in node.names:
                binding[alias.asname or alias.name] = f"{node.module}.{alias.name}"
    return binding
