"""How many test functions start a ROS node or a DDS domain: at most the budget.

The rule (docs/testing.md "Tiers"): a test function is a *node-process test* when the fixtures
it asks for, followed through every fixture they ask for in turn, reach ``ros_domain`` or
``module_domain`` (test/conftest.py ``NODE_FIXTURES``, the same rule that sets the ``node``
marker). Test *functions* are counted, not parametrized cases: a function with four cases is
one. The slow tier counts too. The count is read from the sources (ast), not by collecting
pytest, so this test takes milliseconds; ``test_the_static_count_is_the_marker_rule`` keeps
the two rules the same on a small sample.

What needs no DDS (the driver's behaviour on the bus) runs in the in-process tier instead
(test/support/inprocess.py: master and simulated station on python-can's virtual bus).
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

TEST_ROOT = Path(__file__).resolve().parents[1]
#: the fixtures that give a test a DDS domain of its own (test/conftest.py NODE_FIXTURES)
DOMAIN_FIXTURES = frozenset({"ros_domain", "module_domain"})
#: the budget of node-process test functions
BUDGET = 100
#: the ratchet: the count may not grow above this; lowered with every test moved in-process
#: (182, then 114), now at the budget
CEILING = BUDGET


def _is_fixture(fn: ast.FunctionDef) -> bool:
    for dec in fn.decorator_list:
        target = dec.func if isinstance(dec, ast.Call) else dec
        if isinstance(target, ast.Attribute) and target.attr == "fixture":
            return True
        if isinstance(target, ast.Name) and target.id == "fixture":
            return True
    return False


def _args(fn: ast.FunctionDef) -> set[str]:
    return {a.arg for a in (*fn.args.posonlyargs, *fn.args.args, *fn.args.kwonlyargs)}


def _usefixtures(fn: ast.FunctionDef) -> set[str]:
    names: set[str] = set()
    for dec in fn.decorator_list:
        if (isinstance(dec, ast.Call) and isinstance(dec.func, ast.Attribute)
                and dec.func.attr == "usefixtures"):
            names |= {a.value for a in dec.args if isinstance(a, ast.Constant)}
    return names


def _functions(tree: ast.Module) -> Iterator[tuple[str, ast.FunctionDef]]:
    """Module-level functions and methods of Test* classes, with their class prefix."""
    for node in tree.body:
        if isinstance(node, ast.FunctionDef):
            yield "", node
        elif isinstance(node, ast.ClassDef) and node.name.startswith("Test"):
            for item in node.body:
                if isinstance(item, ast.FunctionDef):
                    yield f"{node.name}::", item


def node_process_tests(root: Path = TEST_ROOT) -> list[str]:
    """``path::function`` of every node-process test function under ``root`` (the rule in
    the module docstring). A fixture name is looked up as pytest does for the test: the test's
    own module first, then the conftest.py of its folder and of each folder above."""
    #: fixtures by defining file: name -> what it asks for
    defs: dict[Path, dict[str, set[str]]] = {}
    tests: list[tuple[Path, str, set[str]]] = []
    #: fixtures a module imports from another test file: (module, name, source file)
    imported: list[tuple[Path, str, Path]] = []
    for path in sorted(root.rglob("*.py")):
        tree = ast.parse(path.read_text(), str(path))
        rel = path.relative_to(root.parent).as_posix()
        own = defs.setdefault(path, {})
        for node in tree.body:
            if isinstance(node, ast.ImportFrom) and node.level > 0 and node.module:
                base = path.parents[node.level - 1]
                source = base.joinpath(*node.module.split(".")).with_suffix(".py")
                imported += [(path, a.asname or a.name, source) for a in node.names]
        for prefix, fn in _functions(tree):
            wants = _args(fn) | _usefixtures(fn)
            if _is_fixture(fn):
                own.setdefault(fn.name, set()).update(wants - {"request", "self"})
            elif fn.name.startswith("test") and path.name.startswith("test_"):
                tests.append((path, f"{rel}::{prefix}{fn.name}", wants))
    for module, name, source in imported:
        if name in defs.get(source, {}):
            defs[module].setdefault(name, set()).update(defs[source][name])

    def chain(module: Path) -> list[dict[str, set[str]]]:
        out = [defs.get(module, {})]
        folder = module.parent
        while True:
            out.append(defs.get(folder / "conftest.py", {}))
            if folder == root or folder == folder.parent:
                return out
            folder = folder.parent

    def reaches(name: str, scope: list[dict[str, set[str]]], seen: frozenset[str]) -> bool:
        if name in DOMAIN_FIXTURES:
            return True
        if name in seen:
            return False
        for level in scope:
            if name in level:
                return any(reaches(dep, scope, seen | {name}) for dep in level[name])
        return False

    return sorted(name for path, name, wants in tests
                  if any(reaches(w, chain(path), frozenset()) for w in wants))


def test_node_process_test_functions_stay_within_the_ceiling():
    found = node_process_tests()
    assert len(found) <= CEILING, (
        f"{len(found)} node-process test functions, ceiling {CEILING} (budget {BUDGET}): "
        "a test that needs no DDS belongs in the in-process tier (docs/testing.md)")


def test_the_static_count_is_the_marker_rule():
    """The ast rule agrees with the fixture resolution pytest does, on tests of each kind:
    a node test through a chain of fixtures, a shared-node test, an in-process test."""
    found = set(node_process_tests())
    assert ("test/ros/test_node_skeleton.py::"
            "test_joint_states_rate_name_stamps_and_speed_and_diagnostics_ok_for_the_joint"
            in found)
    assert "test/ros/test_node_sdo.py::test_sdo_read_of_the_device_type_is_unsigned32_and_an_event" \
        in found  # shared_node -> module_domain
    assert not any(name.startswith("test/packaging/") for name in found)
    assert not any(name.startswith("test/client/") for name in found)
