"""The node owns its parts instead of mixing them in (docs/architecture.md, "Three layers").

A mixin declared the attributes of the class it was mixed into (``settings: Any``, ``cycle:
Any`` ... at class level, set by someone else); a part is constructed with what it needs and
sets every attribute it declares. Both checks fail on the old ``SsiBridgeNode(BridgeLifecycle,
NodeDiagnostics, RuntimeParameters, LifecycleNode)``.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROS = Path(__file__).resolve().parents[2] / "ssi_bridge" / "ros"


def test_the_node_derives_from_rclpy_s_lifecycle_node_alone() -> None:
    from rclpy.lifecycle import LifecycleNode

    from ssi_bridge.ros.node import SsiBridgeNode

    assert SsiBridgeNode.__bases__ == (LifecycleNode,)
    ours = [c.__qualname__ for c in SsiBridgeNode.__mro__ if c.__module__.startswith("ssi_bridge")]
    assert ours == ["SsiBridgeNode"], f"classes of ssi_bridge mixed into the node: {ours}"


def _declared_not_set(cls: ast.ClassDef) -> list[str]:
    """Class-level annotations without a value in a class that is neither a Protocol nor a
    dataclass (where such a declaration is the point)."""
    bases = {ast.unparse(b) for b in cls.bases}
    decorators = {ast.unparse(d).split("(")[0] for d in cls.decorator_list}
    if any("Protocol" in b for b in bases) or decorators & {"dataclass", "dataclasses.dataclass"}:
        return []
    return [ast.unparse(n.target) for n in cls.body
            if isinstance(n, ast.AnnAssign) and n.value is None]


def test_no_class_of_ros_declares_attributes_someone_else_sets() -> None:
    found = {f"{path.name}:{cls.name}": names
             for path in sorted(ROS.glob("*.py"))
             for cls in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
             if isinstance(cls, ast.ClassDef) and (names := _declared_not_set(cls))}
    assert not found, f"attributes declared for another class to set: {found}"
