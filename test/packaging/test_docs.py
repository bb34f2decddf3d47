"""The documentation stands alone: no reference out of the repository, no tracker numbers, the
cited manuals named in one table, command-line help in plain text."""

from __future__ import annotations

import ast
import fnmatch
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
DOCS = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
#: every text a reader of the repository meets: docs, code and its comments, build files
TEXTS = [*DOCS, *sorted(p for d in ("ssi_bridge", "test", "bench", "scripts", "launch", "config")
                         for p in (REPO / d).rglob("*") if p.suffix in {".py", ".yaml", ".sh"}),
         REPO / "Makefile", REPO / "setup.py", REPO / "setup.cfg", REPO / "package.xml",
         REPO / "dependencies.toml", REPO / ".ci" / "run"]
TRACKER = re.compile(r"\bissues?\s*#?\s*\d+", re.IGNORECASE)
#: a ticket by its number alone: "(#22 item 5)"
HASH_TRACKER = re.compile(r"\(#\d+\b|#\d+ item")
OUTSIDE = re.compile(r"\.\./shared|/work/|\bARCHITECTURE\.md")
LINK = re.compile(r"\]\(([^)\s]+)\)")
RST = re.compile(r"``|::\s*$|:(?:ref|class|func|meth|mod):`|^\s*\.\. ", re.MULTILINE)


def rel(path: Path) -> str:
    return str(path.relative_to(REPO))


def test_no_tracker_numbers_in_docs_or_code():
    found = [f"{rel(p)}:{n}" for p in TEXTS if p.exists()
             for n, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
             if TRACKER.search(line)]
    assert not found, f"say what and why, not which ticket: {found}"


def test_no_ticket_numbers_in_docs_or_the_package():
    """The docs and the package's code say what and why, not "(#22 item 5)"."""
    texts = [*DOCS, *sorted((REPO / "ssi_bridge").rglob("*.py"))]
    found = [f"{rel(p)}:{n}" for p in texts
             for n, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
             if HASH_TRACKER.search(line)]
    assert not found, f"say what and why, not which ticket: {found}"


def test_docs_never_point_out_of_the_repository():
    found = [f"{rel(p)}:{n}" for p in DOCS
             for n, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
             if OUTSIDE.search(line)]
    assert not found, f"the repository must stand alone: {found}"
    for page in DOCS:
        for target in LINK.findall(page.read_text(encoding="utf-8")):
            if re.match(r"[a-z]+:|#", target):
                continue
            path = (page.parent / target.split("#", 1)[0]).resolve()
            assert path.is_relative_to(REPO) and path.exists(), f"{rel(page)}: link {target}"


def test_every_cited_manual_is_named_in_the_table():
    table = (REPO / "docs" / "manuals.md").read_text(encoding="utf-8")
    rows = {m.group(1): m.group(0) for m in re.finditer(r"^\| (00\d) \|.*$", table, re.M)}
    cited = set()
    for page in DOCS:
        text = page.read_text(encoding="utf-8")
        names = set(re.findall(r"\b(00\d)(?= (?:§|Table|chapter|ch\.|\"|\)|,))", text))
        names |= set(re.findall(r"manual (00\d)", text))
        if names and page.name != "manuals.md":
            assert "manuals.md" in text, f"{rel(page)} cites {sorted(names)}: point at the table"
        cited |= names
    assert cited and cited <= set(rows), f"manuals cited but not in docs/manuals.md: {cited}"
    for name, row in rows.items():
        cells = [c.strip() for c in row.strip("|").split("|")]
        assert len(cells) == 5 and all(cells), f"{name}: title, maker, number and use"


def console_scripts() -> dict[str, str]:
    """``name -> module`` of setup.py's console_scripts."""
    tree = ast.parse((REPO / "setup.py").read_text(encoding="utf-8"))
    entries = [n.value for n in ast.walk(tree)
               if isinstance(n, ast.Constant) and isinstance(n.value, str) and " = " in n.value]
    entries += ["".join(v.value if isinstance(v, ast.Constant) else "ssi_bridge"
                        for v in n.values) for n in ast.walk(tree) if isinstance(n, ast.JoinedStr)]
    scripts = {}
    for entry in entries:
        if re.fullmatch(r"\w+ = [\w.]+:\w+", entry):
            name, target = entry.split(" = ")
            scripts[name] = target.split(":")[0]
    return scripts


TOOLS = {n: m for n, m in console_scripts().items()
         if n not in ("ssi_bridge_node", "ssi_bridge_managed_node")}  # ROS nodes: --ros-args


def test_the_tools_are_found():
    assert {"replay", "plot"} <= set(TOOLS)


@pytest.mark.parametrize("name", sorted(TOOLS))
def test_help_is_plain_text(name: str):
    out = subprocess.run([sys.executable, "-m", TOOLS[name], "--help"], capture_output=True,
                         text=True, timeout=60, cwd=REPO)
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("usage:")
    markup = RST.findall(out.stdout)
    assert not markup, f"{name} --help shows reStructuredText markup {markup}:\n{out.stdout}"


def test_generated_pictures_are_ignored():
    patterns = [p.strip() for p in (REPO / ".gitignore").read_text().splitlines()]
    for picture in ("session.png", "frame.png"):
        assert any(fnmatch.fnmatch(picture, p) for p in patterns if p), picture


def test_readme_says_who_writes_the_bench_results():
    text = (REPO / "README.md").read_text(encoding="utf-8")
    for paragraph in text.split("\n\n"):
        if "bench/results" in paragraph:
            assert "make bench" in paragraph and "writes" in paragraph, paragraph


def test_readme_explains_the_environment_where_it_shows_the_tools():
    text = (REPO / "README.md").read_text(encoding="utf-8")
    first_tool = text.index("lib/ssi_bridge/replay")
    assert "source scripts/env.sh" in text[:first_tool]


def test_architecture_says_where_each_concept_lives():
    """docs/architecture.md "Where each concept lives" has a line for every module (an
    ``__init__.py`` only when it defines something), in its folder's table."""
    text = (REPO / "docs" / "architecture.md").read_text(encoding="utf-8")
    section = text.split("## Where each concept lives", 1)[1].split("\n## ", 1)[0]
    tables = {m.group(1): m.group(2) for m in re.finditer(
        r"^\*\*`(\w+)/`\*\*.*?\n(.*?)(?=^\*\*`|\Z)", section, re.M | re.S)}
    missing = []
    for path in sorted((REPO / "ssi_bridge").rglob("*.py")):
        parts = path.relative_to(REPO / "ssi_bridge").parts
        if len(parts) == 1:
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        if path.name == "__init__.py" and not any(
                isinstance(n, (ast.FunctionDef, ast.ClassDef)) for n in tree.body):
            continue
        name = "/".join(parts[1:])
        if not re.search(rf"`{re.escape(name)}`", tables.get(parts[0], "")):
            missing.append("/".join(parts))
    assert not missing, f"modules without their concept in docs/architecture.md: {missing}"
