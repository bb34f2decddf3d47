"""Polling without a fixed sleep: wait until a condition holds, fail the test when it does
not within its time."""

from __future__ import annotations

import time
from collections.abc import Callable

import pytest


def wait_for(condition: Callable[[], object], message: str, timeout: float = 2.0,
             poll: float = 0.001) -> None:
    """Poll ``condition`` every ``poll`` s until true; fail with ``message`` after
    ``timeout`` s."""
    end = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > end:
            pytest.fail(message)
        time.sleep(poll)
