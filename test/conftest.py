"""Fixtures shared by every test folder."""

from __future__ import annotations

import fcntl
import os
import random
from collections.abc import Callable, Iterator
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


@pytest.fixture
def small_fs(tmp_path: Path) -> Iterator[Callable[[int], Path]]:
    """Factory: a tmpfs of ``size`` bytes mounted under tmp_path (root only), unmounted after.

    A real file system that runs full (ENOSPC), for the write-error paths of the recorders.
    """
    import subprocess

    if os.geteuid() != 0:
        pytest.skip("mounting a small file system needs root")
    mounted: list[Path] = []

    def _mount(size: int) -> Path:
        point = tmp_path / f"small_fs{len(mounted)}"
        point.mkdir()
        done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size},mode=0777", "tmpfs",
                               str(point)], capture_output=True, text=True)
        if done.returncode != 0:
            pytest.skip(f"cannot mount a tmpfs: {done.stderr.strip()}")
        mounted.append(point)
        return point

    _mount.fill = fill_up  # type: ignore[attr-defined]
    yield _mount
    for point in mounted:
        subprocess.run(["umount", "-l", str(point)], check=False)


def fill_up(directory: Path) -> Path:
    """Write a filler file until ``directory``'s file system is full (ENOSPC)."""
    filler = directory / "filler"
    fd = os.open(filler, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    try:
        for block in (65536, 4096, 512, 1):
            try:
                while True:
                    os.write(fd, b"\0" * block)
            except OSError:
                pass  # ENOSPC: go on with smaller blocks down to the last byte
    finally:
        os.close(fd)
    return filler
