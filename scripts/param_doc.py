"""Write docs/parameters.md, the table of every node parameter, from ssi_bridge/ros/param_table.py.

Usage (in the project's environment, ``source scripts/env.sh``): ``python scripts/param_doc.py``
rewrites the page; ``python scripts/param_doc.py --check`` exits 1 if the page is not what the
table gives. ``test/packaging/test_param_doc.py`` runs the check, so the page cannot go stale:
a parameter added, removed or changed in the table fails the test until the page is written
again.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
PAGE = REPO / "docs" / "parameters.md"

HEAD = """\
# Parameters

Every parameter of the node, generated from `ssi_bridge/ros/param_table.py` by
`python scripts/param_doc.py` (a test checks that this page is what the table gives). With a
ROS 2 install, `ros2 param describe /ssi_bridge <name>` shows the same descriptions and
ranges. "Run time: yes" means `ros2 param set` (or the live view's Parameters panel) changes it
while the node runs, checked first (docs/node.md, "Parameters"); every other parameter is
read-only once the node started and is given at start-up (`-p name:=value` or a params file).
A parameter the node does not know (a typo) is warned about at start-up with the closest name.
The manuals cited as 000-004 are listed in `docs/manuals.md`.
"""


def _number(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return f"0x{value:08X}" if value > 0xFFFFFF else str(value)
    if isinstance(value, float):  # 100.0, not 100: `-p publish_rate:=100` is an integer
        return f"{value:.1f}" if value.is_integer() and abs(value) < 1e6 else f"{value:g}"
    return repr(value)


def _default(value: Any) -> str:
    if isinstance(value, str):
        return f'`"{value}"`'
    if isinstance(value, list):
        return "`[" + ", ".join(_number(v) if not isinstance(v, str) else v
                                for v in value) + "]`"
    return f"`{_number(value)}`"


def _range(descriptor: Any) -> str:
    if descriptor.integer_range:
        r = descriptor.integer_range[0]
        return f"{_number(r.from_value)} … {_number(r.to_value)}"
    if descriptor.floating_point_range:
        r = descriptor.floating_point_range[0]
        return f"{_number(r.from_value)} … {_number(r.to_value)}"
    return ""


def _rows(table: dict[str, tuple[Any, Any]], prefix: str) -> list[str]:
    rows = ["| name | default | range | run time | meaning |", "|---|---|---|---|---|"]
    for name, (default, descriptor) in table.items():
        # a table cell: '|' would end it, '<joint>' would be read as an HTML tag
        meaning = " ".join(descriptor.description.split()).replace("|", "\\|").replace(
            "<", "\\<")
        rows.append(f"| `{prefix}{name}` | {_default(default)} | {_range(descriptor)} | "
                    f"{'no' if descriptor.read_only else 'yes'} | {meaning} |")
    return rows


def render() -> str:
    """The page's text from the parameter table."""
    from ssi_bridge.ros.param_table import JOINT_PARAMETERS, NODE_PARAMETERS

    lines = [HEAD, "## Node-wide", "", *_rows(NODE_PARAMETERS, ""), "",
             "## Per joint", "",
             "Declared for each name in `joints`, as `<joint>.<name>` (e.g. `joint1.para1`).",
             "", *_rows(JOINT_PARAMETERS, "<joint>."), ""]
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    text = render()
    if "--check" in argv:
        if not PAGE.exists() or PAGE.read_text(encoding="utf-8") != text:
            print(f"{PAGE.relative_to(REPO)} is stale: run python scripts/param_doc.py",
                  file=sys.stderr)
            return 1
        return 0
    PAGE.write_text(text, encoding="utf-8")
    print(f"wrote {PAGE.relative_to(REPO)}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
