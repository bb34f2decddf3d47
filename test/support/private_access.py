"""The scanner behind test/packaging/test_private_access.py: which lines of a module touch a
private part of python-can, canopen or rclpy (the rule: that test's docstring and
docs/architecture.md "Library adapters").

What is private is read from the installed libraries themselves, not listed here:

* ``private``: every ``_name`` (not a dunder) the libraries' sources define or use as an
  attribute, a function, a method or a class;
* ``hooks``: the private methods whose docstring invites a subclass to override them
  (python-can's ``BusABC._recv_internal``, ``_send_periodic_internal``, ...);
* ``config``: the UPPER_CASE class attributes of the libraries' classes (canopen's
  ``Network.NOTIFIER_CYCLE``, ``SdoClient.RESPONSE_TIMEOUT``, ...);
* ``tables``: the containers a library object keeps its registrations in (an attribute its
  class's own methods change in place: ``Network.subscribers``, ``Network.nodes``,
  ``Notifier.listeners``, ``LocalNode.data_store``, ...);
* per library class, the private names of its own code (its MRO's sources and ``__dict__``).
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


def _is_container(value: ast.expr | None) -> bool:
    """A new list, dict or set."""
    if isinstance(value, (ast.List, ast.Dict, ast.Set, ast.ListComp, ast.DictComp,
                          ast.SetComp)):
        return True
    return (isinstance(value, ast.Call) and isinstance(value.func, ast.Name)
            and value.func.id in ("list", "dict", "set"))


def _is_private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def _is_config(name: str) -> bool:
    return len(name) > 1 and name.isupper() and not name.startswith("_")


def _targets(node: ast.AST) -> list[ast.expr]:
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
            if isinstance(node, ast.Attribute) and _is_private(node.attr):
                private.add(node.attr)
            elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                if _is_private(node.name):
                    private.add(node.name)
                    doc = ast.get_docstring(node) or ""
                    if not isinstance(node, ast.ClassDef) and re.search(r"overrid|\bhook\b",
                                                                        doc, re.I):
                        hooks.add(node.name)
                if isinstance(node, ast.ClassDef):
                    for item in node.body:
                        for target in _targets(item):
                            if isinstance(target, ast.Name) and _is_config(target.id):
                                config.add(target.id)
            changed: ast.expr | None = None
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) \
                    and node.func.attr in MUTATORS:
                changed = node.func.value
            for target in _targets(node):
                if isinstance(target, ast.Subscript):
                    changed = target.value
            while isinstance(changed, (ast.Call, ast.Subscript)):  # d.setdefault(k, {})[i] =
                changed = changed.func if isinstance(changed, ast.Call) else changed.value
                if isinstance(changed, ast.Attribute) and changed.attr in MUTATORS:
                    changed = changed.value
            if (isinstance(changed, ast.Attribute) and isinstance(changed.value, ast.Name)
                    and changed.value.id == "self" and not _is_private(changed.attr)):
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


@dataclass
class _Scope:
    """The class (and method) a node is in."""

    library: tuple[type, ...] = ()  #: the library classes the class derives from
    names: frozenset[str] = frozenset()  #: what their code defines or uses on self
    method: str = ""


class Scanner(ast.NodeVisitor):
    """Finds the library-private accesses of one module (:attr:`found`: ``line: what``).

    :param tree: the module
    :param binding: its imports (:func:`import_bindings`)
    :param classes: the package's classes (to tell its own from library-derived ones)
    :param facts: what the libraries keep private
    """

    def __init__(self, tree: ast.Module, binding: dict[str, str], classes: ProjectClasses,
                 facts: Facts) -> None:
        self.classes = classes
        self.facts = facts
        self.binding = binding
        self.uses_rclpy = any(v.split(".")[0] == "rclpy" for v in self.binding.values())
        self.scope = _Scope()
        self.found: list[str] = []
        self.own = self._own_names(tree)
        self.visit(tree)

    # -- what this module defines itself -------------------------------------------------
    def _own_names(self, tree: ast.Module) -> frozenset[str]:
        """Names the module's own (not library-derived) classes define on ``self``/``cls``
        or in their body, and the module's top-level names: its objects' attributes."""
        own: set[str] = set()
        for node in tree.body:
            own.update(t.id for t in _targets(node) if isinstance(t, ast.Name))
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                own.add(node.name)
        for node in ast.walk(tree):
            if not isinstance(node, ast.ClassDef):
                continue
            if self.classes.library_bases(node.bases, self.binding):
                continue
            for item in ast.walk(node):
                if isinstance(item, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    own.add(item.name)
                for target in _targets(item):
                    if isinstance(target, ast.Name):
                        own.add(target.id)
                    elif isinstance(target, ast.Attribute) and isinstance(
                            target.value, ast.Name) and target.value.id in ("self", "cls"):
                        own.add(target.attr)
        return frozenset(own)

    def _say(self, node: ast.AST, what: str) -> None:
        self.found.append(f"{getattr(node, 'lineno', 0)}: {what}")

    # -- scopes ----------------------------------------------------------------------------
    def visit_ClassDef(self, node: ast.ClassDef) -> None:
        outer = self.scope
        library = tuple(self.classes.library_bases(node.bases, self.binding))
        names: set[str] = set()
        for cls in library:
            names.update(class_names(cls))
        self.scope = _Scope(library, frozenset(names))
        if library:
            for item in node.body:
                for target in _targets(item):
                    if isinstance(target, ast.Name) and _is_config(target.id) \
                            and target.id in self.scope.names:
                        self._say(item, f"class {node.name} overrides {target.id} of "
                                        f"{library[0].__qualname__}")
        self.generic_visit(node)
        self.scope = outer

    def _visit_function(self, node: ast.FunctionDef | ast.AsyncFunctionDef) -> None:
        scope = self.scope
        if scope.library and scope.method == "" and _is_private(node.name) \
                and node.name in scope.names and node.name not in self.facts.hooks:
            self._say(node, f"overrides the private method {node.name} of "
                            f"{scope.library[0].__qualname__}")
        if scope.method == "":  # a method (nested functions keep their method's scope)
            self.scope = _Scope(scope.library, scope.names, node.name)
        self.generic_visit(node)
        self.scope = scope

    visit_FunctionDef = _visit_function
    visit_AsyncFunctionDef = _visit_function

    # -- the checks --------------------------------------------------------------------------
    def _private_access(self, node: ast.AST, receiver: ast.expr, name: str) -> None:
        """``receiver.name`` with a private ``name``."""
        scope = self.scope
        is_self = isinstance(receiver, ast.Name) and receiver.id in ("self", "cls")
        is_super = (isinstance(receiver, ast.Call) and isinstance(receiver.func, ast.Name)
                    and receiver.func.id == "super")
        if (is_self or is_super) and scope.method:
            if not scope.library or name not in scope.names:
                return  # the class's own private
            if is_super and name == scope.method and name in self.facts.hooks:
                return  # an override of a documented hook calls the default
            self._say(node, f"{ast.unparse(receiver)}.{name}: private to "
                            f"{scope.library[0].__qualname__}")
            return
        if name in self.facts.private and name not in self.own:
            self._say(node, f"{ast.unparse(receiver)}.{name}: a private name of "
                            f"{'/'.join(LIBRARIES)}")

    def visit_Attribute(self, node: ast.Attribute) -> None:
        if _is_private(node.attr):
            self._private_access(node, node.value, node.attr)
        if (self.uses_rclpy and isinstance(node.value, ast.Attribute)
                and node.value.attr == "handle"):
            self._say(node, f"{ast.unparse(node)}: rclpy's implementation object (handle)")
        self.generic_visit(node)

    def visit_Call(self, node: ast.Call) -> None:
        func = node.func
        if (isinstance(func, ast.Name) and func.id in ("getattr", "setattr", "hasattr",
                                                       "delattr")
                and len(node.args) > 1 and isinstance(node.args[1], ast.Constant)
                and isinstance(node.args[1].value, str) and _is_private(node.args[1].value)):
            self._private_access(node, node.args[0], node.args[1].value)
        if (isinstance(func, ast.Attribute) and func.attr in MUTATORS
                and isinstance(func.value, ast.Attribute)):
            self._table_write(node, func.value)
        self.generic_visit(node)

    def visit_With(self, node: ast.With) -> None:
        for item in node.items:
            expr = item.context_expr
            if self.uses_rclpy and isinstance(expr, ast.Attribute) and expr.attr == "handle":
                self._say(node, f"with {ast.unparse(expr)}: rclpy's implementation object")
        self.generic_visit(node)

    def _table_write(self, node: ast.AST, attr: ast.Attribute) -> None:
        """A change of the container ``attr`` in place, or ``attr`` replaced."""
        name = attr.attr
        if name not in self.facts.tables:
            return
        receiver = attr.value
        if isinstance(receiver, ast.Name) and receiver.id in ("self", "cls") \
                and self.scope.method:
            if self.scope.library and name in self.scope.names:
                self._say(node, f"{ast.unparse(attr)}: the registry of "
                                f"{self.scope.library[0].__qualname__}, changed")
            return
        if name not in self.own:
            self._say(node, f"{ast.unparse(attr)}: a library object's registry, changed")

    def _write(self, node: ast.AST) -> None:
        for target in _targets(node):
            if isinstance(target, ast.Subscript) and isinstance(target.value, ast.Attribute):
                self._table_write(node, target.value)
            elif isinstance(target, ast.Attribute):
                if _is_config(target.attr) and target.attr in self.facts.config \
                        and target.attr not in self.own:
                    self._say(node, f"{ast.unparse(target)} = ...: a library class's "
                                    f"setting, set")
                elif _is_container(getattr(node, "value", None)):
                    self._table_write(node, target)  # a registry replaced by a new one

    def visit_Assign(self, node: ast.Assign) -> None:
        self._write(node)
        self.generic_visit(node)

    visit_AugAssign = visit_Assign  # type: ignore[assignment]
    visit_AnnAssign = visit_Assign  # type: ignore[assignment]
    visit_Delete = visit_Assign  # type: ignore[assignment]

    def _module(self, node: ast.AST, module: str) -> None:
        parts = module.split(".")
        if parts[0] in LIBRARIES and any(_is_private(p) or p in INTERNAL_PARTS
                                         for p in parts[1:]):
            self._say(node, f"imports {module}: not the library's API")

    def visit_Import(self, node: ast.Import) -> None:
        for alias in node.names:
            self._module(node, alias.name)

    def visit_ImportFrom(self, node: ast.ImportFrom) -> None:
        if node.module and not node.level:
            self._module(node, node.module)
            if node.module.split(".")[0] in LIBRARIES:
                for alias in node.names:
                    if _is_private(alias.name):
                        self._say(node, f"imports {node.module}.{alias.name}: private")


def scan(sources: dict[str, str], facts: Facts | None = None) -> list[str]:
    """``path:line: what`` for each library-private access in ``sources`` (path -> text),
    the adapters (:data:`ADAPTERS`) left out."""
    facts = facts or library_facts()
    trees = {path: ast.parse(text, filename=path) for path, text in sources.items()}
    bindings = {path: import_bindings(tree) for path, tree in trees.items()}
    classes = ProjectClasses()
    for path, tree in trees.items():
        classes.add_module(tree, bindings[path])
    found: list[str] = []
    for path, tree in sorted(trees.items()):
        if path in ADAPTERS:
            continue
        scanner = Scanner(tree, bindings[path], classes, facts)
        found.extend(f"{path}:{line}" for line in scanner.found)
    return found
