"""Every third-party import is declared: package.xml, the requirements files and the table
dependencies.toml agree, so a workspace user's `rosdep install` + pip installs what the code
imports.

The imports are read from the code (ast), not listed by hand: a new import without a row in
dependencies.toml fails here. With SSI_BRIDGE_ROSDISTRO naming a ros/rosdistro checkout (a work
tree or a git directory), each key is also looked up in rosdep/python.yaml, rosdep/base.yaml
and jazzy/distribution.yaml.
"""

from __future__ import annotations

import ast
import os
import re
import shlex
import subprocess
import sys
import tomllib
from functools import cache
from pathlib import Path

import pytest
import yaml
from catkin_pkg.package import parse_package
from catkin_pkg.packages import find_packages

REPO = Path(__file__).resolve().parents[2]
TABLE = REPO / "dependencies.toml"
README = REPO / "README.md"
SOURCES = {"run": [REPO / "ssi_bridge", REPO / "launch"], "test": [REPO / "test"]}


def imported_modules(roots: list[Path]) -> dict[str, set[str]]:
    """Top-level modules imported (absolute imports, anywhere in a file) -> files importing them."""
    found: dict[str, set[str]] = {}
    for root in roots:
        for path in sorted(root.rglob("*.py")):
            tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
            for node in ast.walk(tree):
                if isinstance(node, ast.Import):
                    names = [alias.name for alias in node.names]
                elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                    names = [node.module]
                else:
                    continue
                for name in names:
                    found.setdefault(name.split(".")[0], set()).add(
                        str(path.relative_to(REPO)))
    return found


def third_party(found: dict[str, set[str]], local: set[str]) -> dict[str, set[str]]:
    """Drop the standard library, this package and modules that live beside the tests."""
    skip = set(sys.stdlib_module_names) | {"__future__", "ssi_bridge"} | local
    return {m: files for m, files in found.items() if m not in skip}


def local_test_modules() -> set[str]:
    """Modules a test imports from its own folder (``conftest``, helper scripts) and the
    test-side packages (``support``)."""
    tests = REPO / "test"
    return ({p.stem for p in tests.rglob("*.py")}
            | {p.parent.name for p in tests.rglob("__init__.py")})


@cache
def table() -> dict:
    return tomllib.loads(TABLE.read_text(encoding="utf-8"))


@cache
def package(path: Path):
    return parse_package(str(path))


def normalize(requirement: str) -> str:
    """``PyYAML==6.0.3`` -> ``pyyaml==6.0.3`` (PEP 503 name, version kept)."""
    name, _, version = requirement.partition("==")
    return re.sub(r"[-_.]+", "-", name).lower() + "==" + version


def requirements(path: Path, follow: bool = True) -> set[str]:
    """The pins of a requirements file (``name==version``), following ``-r`` includes."""
    pins: set[str] = set()
    for raw in path.read_text(encoding="utf-8").splitlines():
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        if line.startswith("-r"):
            if follow:
                pins |= requirements(path.parent / line[2:].strip())
            continue
        assert "==" in line, f"{path.name}: {line!r} is not an exact pin"
        pins.add(normalize(re.sub(r"\[.*?\]", "", line.split(";")[0]).strip()))
    return pins


def declared(pkg) -> dict[str, set[str]]:
    """package.xml dependency names by tag (``depend`` counts as build and exec)."""
    return {
        "exec": {d.name for d in pkg.exec_depends},
        "build": {d.name for d in pkg.build_depends},
        "test": {d.name for d in pkg.test_depends},
        "all": {d.name for d in (*pkg.build_depends, *pkg.exec_depends, *pkg.test_depends,
                                 *pkg.buildtool_depends, *pkg.build_export_depends)},
    }


def test_every_import_of_the_package_has_a_row():
    run = third_party(imported_modules(SOURCES["run"]), set())
    missing = {m: sorted(f)[:3] for m, f in run.items() if m not in table()["run"]}
    assert not missing, (
        f"imported but not in dependencies.toml [run] (add a row, then package.xml and the "
        f"requirements files): {missing}")
    stale = set(table()["run"]) - set(run)
    assert not stale, f"dependencies.toml [run] lists modules nothing imports: {sorted(stale)}"


def test_every_import_of_the_tests_has_a_row():
    run = set(table()["run"])
    tests = third_party(imported_modules(SOURCES["test"]), local_test_modules())
    missing = {m: sorted(f)[:3] for m, f in tests.items()
               if m not in run and m not in table()["test"]}
    assert not missing, f"imported by tests but not in dependencies.toml [test]: {missing}"
    stale = set(table()["test"]) - set(tests)
    assert not stale, f"dependencies.toml [test] lists modules no test imports: {sorted(stale)}"
    both = set(table()["test"]) & run
    assert not both, f"{sorted(both)}: a run dependency covers the tests too (REP 149)"


def rows() -> list[tuple[str, str, dict]]:
    """``(what, scope, row)`` of every row: [run] and [test] per module, [extra] per key."""
    out = [(f"import {m}", "run", r) for m, r in table()["run"].items()]
    out += [(f"test import {m}", "test", r) for m, r in table()["test"].items()]
    for key, row in table().get("extra", {}).items():
        scope = {"exec_depend": "run", "depend": "run", "test_depend": "test"}[row["tag"]]
        out.append((f"{key} ({row['uses']})", scope, {"pip": "", **row, "key": key}))
    return out


def test_package_xml_declares_exactly_the_table():
    deps = declared(package(REPO / "package.xml"))
    expected: set[str] = set()
    for what, scope, row in rows():
        if not row["key"]:
            continue
        tag = "<exec_depend> or <depend>" if scope == "run" else "<test_depend>"
        assert row["key"] in deps["exec" if scope == "run" else "test"], \
            f"{what}: package.xml needs {tag} {row['key']}"
        expected.add(row["key"])
    undeclared = deps["all"] - expected
    assert not undeclared, \
        f"package.xml keys without a row in dependencies.toml: {sorted(undeclared)}"


def test_rows_are_complete_and_pip_only_packages_go_to_the_workspace_files():
    for what, _, row in rows():
        assert row["source"] in {"python.yaml", "base.yaml", "jazzy", "repository", ""}, what
        assert bool(row["key"]) == bool(row["source"]), what
        if row["source"] in {"python.yaml", "base.yaml"}:
            assert row.get("via") in {"apt", "pip"}, f"{what}: via = 'apt' or 'pip'"
            assert row["pip"], f"{what}: a rosdep key of a Python package needs its pin"
        if (not row["key"] or row.get("via") == "pip") and not row.get("optional"):
            assert row.get("workspace"), \
                f"{what}: rosdep does not install it from the system, so pip must " \
                f"(workspace = true; or optional = true for a feature that is off by default)"
        if not row["key"]:
            assert row["pip"], f"{what}: without a rosdep key only its pin can install it"
        if row["source"] in {"jazzy", "repository"}:
            assert not row["pip"] and not row.get("workspace"), \
                f"{what}: a ROS package comes from the ROS install, never from pip"


def test_pins_agree_with_requirements_in_and_the_lock():
    direct = requirements(REPO / "requirements.in")
    lock = requirements(REPO / "requirements.lock")
    for what, _, row in rows():
        if not row["pip"]:
            continue
        pin = normalize(row["pip"])
        assert pin in direct, f"{what}: {row['pip']} missing from requirements.in"
        assert pin in lock, f"{what}: requirements.lock does not pin {row['pip']}"


@pytest.mark.parametrize(("scope", "name"), [
    ("run", "requirements-workspace.txt"), ("test", "requirements-workspace-test.txt")])
def test_workspace_files_hold_exactly_the_pip_installs(scope: str, name: str):
    pins = requirements(REPO / name, follow=False)
    wanted = {normalize(r["pip"]) for _, s, r in rows() if s == scope and r.get("workspace")}
    assert pins == wanted, f"{name} must pin exactly the {scope} rows with workspace = true"
    if scope == "test":
        assert "-r requirements-workspace.txt" in (REPO / name).read_text(encoding="utf-8")


def test_the_short_runtime_file_is_non_ros():
    pins = requirements(REPO / "requirements-workspace.txt", follow=False)
    assert not [p for p in pins if p.startswith("ros-")], "ROS comes from /opt/ros, not pip"
    assert {p.split("==")[0] for p in pins} >= {"python-can", "canopen", "mcap"}


# --- the nested msg_defs/ package ---------------------------------------------------------------

def test_both_package_xml_files_parse_and_validate():
    for path in (REPO / "package.xml", REPO / "msg_defs" / "package.xml"):
        package(path).validate()
    assert package(REPO / "msg_defs" / "package.xml").name == "ssi_bridge_msgs"


def test_msg_defs_declares_the_message_packages_its_interfaces_use():
    used: set[str] = set()
    for path in [*(REPO / "msg_defs").glob("msg/*.msg"), *(REPO / "msg_defs").glob("srv/*.srv")]:
        for raw in path.read_text(encoding="utf-8").splitlines():
            field = raw.split("#", 1)[0].split()
            if field and "/" in field[0]:
                used.add(field[0].split("/")[0])
    deps = declared(package(REPO / "msg_defs" / "package.xml"))
    assert used and used <= deps["build"] & deps["exec"], \
        f"msg_defs/package.xml must <depend> on {sorted(used)}"


def readme_workspace_commands() -> list[list[str]]:
    """The shell commands of README's workspace section, continuation lines joined."""
    text = README.read_text(encoding="utf-8")
    section = text.split("## In a ROS 2 Jazzy workspace", 1)[1].split("\n## ", 1)[0]
    block = section.split("```bash", 1)[1].split("```", 1)[0].replace("\\\n", " ")
    return [shlex.split(line, comments=True) for line in block.splitlines()
            if line.strip() and not line.strip().startswith("#")]


def test_catkin_finds_only_ssi_bridge_so_the_readme_names_msg_defs():
    """rosdep and colcon stop at the repository's package.xml and never see msg_defs/: the
    README's rosdep and colcon lines must name both paths."""
    assert [p.name for p in find_packages(str(REPO)).values()] == ["ssi_bridge"]
    assert [p.name for p in find_packages(str(REPO / "msg_defs")).values()] == \
        ["ssi_bridge_msgs"]
    commands = readme_workspace_commands()
    rosdep = [c for c in commands if c[:2] == ["rosdep", "install"]]
    assert len(rosdep) == 1
    paths = rosdep[0][rosdep[0].index("--from-paths") + 1:]
    assert paths[:2] == ["src/ssi_bridge", "src/ssi_bridge/msg_defs"] and "--ignore-src" in paths
    colcon = [c for c in commands if "colcon" in c and ("build" in c or "test" in c)]
    assert len(colcon) == 2
    for c in colcon:
        start = c.index("--base-paths") + 1
        assert c[start:start + 2] == ["src", "src/ssi_bridge/msg_defs"], c


def test_readme_rosdep_skips_exactly_the_pip_keys():
    """rosdep would run pip as root into the system Python (refused on Ubuntu 24.04, PEP 668):
    those keys are skipped and come from the workspace files into the venv."""
    rosdep = next(c for c in readme_workspace_commands() if c[:2] == ["rosdep", "install"])
    skipped = set(rosdep[rosdep.index("--skip-keys") + 1].split())
    pip_keys = {r["key"] for _, _, r in rows() if r.get("via") == "pip"}
    assert skipped == pip_keys


# --- optional: the keys against a ros/rosdistro checkout -----------------------------------------

def rosdistro_file(name: str) -> str:
    root = os.environ.get("SSI_BRIDGE_ROSDISTRO", "")
    if not root:
        pytest.skip("SSI_BRIDGE_ROSDISTRO (a ros/rosdistro checkout or git dir) not set")
    path = Path(root) / name
    if path.is_file():
        return path.read_text(encoding="utf-8")
    return subprocess.run(["git", "--git-dir", root, "show", f"HEAD:{name}"], check=True,
                          capture_output=True, text=True).stdout


@cache
def rosdistro(name: str) -> dict:
    return yaml.safe_load(rosdistro_file(name))


def jazzy_packages() -> set[str]:
    names: set[str] = set()
    for repo, entry in rosdistro("jazzy/distribution.yaml")["repositories"].items():
        release = entry.get("release") or {}
        names |= set(release.get("packages", [repo] if release else []))
    return names


def test_keys_exist_in_rosdistro():
    jazzy = jazzy_packages()
    for _, _, row in rows():
        if row["source"] == "jazzy":
            assert row["key"] in jazzy, f"{row['key']} is not a ROS 2 Jazzy package"
        elif row["source"] in {"python.yaml", "base.yaml"}:
            entry = rosdistro(f"rosdep/{row['source']}").get(row["key"])
            assert entry is not None, f"{row['key']} is not in rosdep/{row['source']}"
            ubuntu = entry.get("ubuntu")
            assert ubuntu is not None, f"{row['key']}: no Ubuntu rule"
            pip = isinstance(ubuntu, dict) and "pip" in ubuntu
            assert pip == (row["via"] == "pip"), f"{row['key']}: Ubuntu installs it with " \
                f"{'pip' if pip else 'apt'}, the table says {row['via']}"
    repository = {"ssi_bridge", "ssi_bridge_msgs"}
    for path in (REPO / "package.xml", REPO / "msg_defs" / "package.xml"):
        for key in declared(package(path))["all"]:
            known = key in jazzy or key in repository or any(
                key in rosdistro(f"rosdep/{f}") for f in ("python.yaml", "base.yaml"))
            assert known, f"{path.relative_to(REPO)}: {key} is no rosdep key"


def test_pytest_runs_with_the_repository_options(request: pytest.FixtureRequest):
    """`make test` and `colcon test` (which starts pytest in the package's source directory)
    both read setup.cfg: same import mode, same markers, same warnings filter."""
    assert request.config.inipath == REPO / "setup.cfg"
    assert request.config.getoption("importmode") == "importlib"


def test_colcon_test_runs_pytest():
    """colcon picks pytest for an ament_python package only when setup.py names it as a test
    extra; otherwise `colcon test` runs unittest and finds no test."""
    tree = ast.parse((REPO / "setup.py").read_text(encoding="utf-8"))
    extras = [kw.value for node in ast.walk(tree) if isinstance(node, ast.Call)
              for kw in node.keywords if kw.arg == "extras_require"]
    assert len(extras) == 1 and "pytest" in ast.literal_eval(extras[0]).get("test", [])
