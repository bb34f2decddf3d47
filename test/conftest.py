"""Fixtures shared by every test folder."""

from __future__ import annotations

import fcntl
import os
import random
from collections.abc import Iterator
from pathlib import Path

import pytest

#: DDS domain ids a test may take (Fast DDS's default port mapping allows 0-232; 0 is left to
#: users). Claims are flock()ed files, so parallel test runs on one machine never share one.
DOMAIN_IDS = range(1, 233)
CLAIMS = Path(os.environ.get("TMPDIR", "/tmp")) / "ssi_bridge_test_domains"


def claim_domain() -> tuple[int, int]:
    """A ROS_DOMAIN_ID no other running test holds, and the fd holding it (close to release).

    The lock dies with the process, so a killed test run leaves no claim behind.
    """
    CLAIMS.mkdir(parents=True, exist_ok=True)
    ids = list(DOMAIN_IDS)
    random.Random(os.getpid() ^ os.urandom(4)[0] << 8).shuffle(ids)
    for dom in ids:
        fd = os.open(CLAIMS / f"{dom}.lock", os.O_CREAT | os.O_RDWR, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            continue
        return dom, fd
    raise RuntimeError(f"every DDS domain id {DOMAIN_IDS} is held by a running test")


@pytest.fixture
def ros_domain() -> Iterator[int]:
    """A test-unique ROS_DOMAIN_ID, held until the test ends."""
    dom, fd = claim_domain()
    try:
        yield dom
    finally:
        os.close(fd)
