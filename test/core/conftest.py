"""Fixtures of the core tests: the in-process tier (test/support/inprocess.py)."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

import pytest

from support.inprocess import InProcessBridge


@pytest.fixture
def inprocess() -> Iterator[Callable[..., InProcessBridge]]:
    """Factory: the node's bus side and its simulated station in this process, with these
    node parameter values (dotted names); every one started is closed after the test."""
    started: list[InProcessBridge] = []

    def _start(values: dict[str, Any] | None = None, **kwargs: Any) -> InProcessBridge:
        bridge = InProcessBridge(values or {}, **kwargs)
        started.append(bridge)
        return bridge

    yield _start
    for bridge in started:
        bridge.close()
