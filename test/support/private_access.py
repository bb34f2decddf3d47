"""The scanner behind test/packaging/test_private_access.py: which lines of a module touch a
private part of python-can, canopen or rclpy (the rule: that test's docstring and
docs/architecture.md "Library adapters"); what is private: ``library_private.py``.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass

from support.library_private import (
    ADAPTERS, INTERNAL_PARTS, LIBRARIES, MUTATORS, Facts, ProjectClasses, class_names,
    import_bindings, is_config, is_container, is_private, library_facts, targets,
)

__all__ = ["ADAPTERS", "LIBRARIES", "Scanner", "library_facts", "scan"]


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
        for top in tree.body:
            own.update(t.id for t in targets(top) if isinstance(t, ast.Name))
            if isinstance(top, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                own.add(top.name)
        for node in ast.walk(tree):
            if not isinstance(node, ast.ClassDef):
                continue
            if self.classes.library_bases(node.bases, self.binding):
                continue
            for item in ast.walk(node):
                if isinstance(item, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    own.add(item.name)
                for target in targets(item):
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
                for target in targets(item):
                    if isinstance(target, ast.Name) and is_config(target.id) \
                            and target.id in self.scope.names:
                        self._say(item, f"class {node.name} overrides {target.id} of "
                                        f"{library[0].__qualname__}")
        self.generic_visit(node)
        self.scope = outer

    def _visit_function(self, node: ast.FunctionDef | ast.AsyncFunctionDef) -> None:
        scope = self.scope
        if scope.library and scope.method == "" and is_private(node.name) \
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
        if is_private(node.attr):
            self._private_access(node, node.value, node.attr)
        if (self.uses_rclpy and isinstance(node.value, ast.Attribute)
                and node.value.attr == "handle"):
            self._say(node, f"{ast.unparse(node)}: rclpy's implementation object (handle)")
        if node.attr in INTERNAL_PARTS and isinstance(node.value, (ast.Name, ast.Attribute)):
            root = ast.unparse(node.value).split(".")[0]
            if self.binding.get(root, "").split(".")[0] in LIBRARIES:
                self._say(node, f"{ast.unparse(node)}: not the library's API")
        self.generic_visit(node)

    def visit_Call(self, node: ast.Call) -> None:
        func = node.func
        if (isinstance(func, ast.Name) and func.id in ("getattr", "setattr", "hasattr",
                                                       "delattr")
                and len(node.args) > 1 and isinstance(node.args[1], ast.Constant)
                and isinstance(node.args[1].value, str) and is_private(node.args[1].value)):
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
        for target in targets(node):
            if isinstance(target, ast.Subscript) and isinstance(target.value, ast.Attribute):
                self._table_write(node, target.value)
            elif isinstance(target, ast.Attribute):
                if is_config(target.attr) and target.attr in self.facts.config \
                        and target.attr not in self.own:
                    self._say(node, f"{ast.unparse(target)} = ...: a library class's "
                                    f"setting, set")
                elif is_container(getattr(node, "value", None)):
                    self._table_write(node, target)  # a registry replaced by a new one

    def visit_Assign(self, node: ast.Assign) -> None:
        self._write(node)
        self.generic_visit(node)

    visit_AugAssign = visit_Assign  # type: ignore[assignment]
    visit_AnnAssign = visit_Assign  # type: ignore[assignment]
    visit_Delete = visit_Assign  # type: ignore[assignment]

    def _module(self, node: ast.AST, module: str) -> None:
        parts = module.split(".")
        if parts[0] in LIBRARIES and any(is_private(p) or p in INTERNAL_PARTS
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
                    if is_private(alias.name):
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
