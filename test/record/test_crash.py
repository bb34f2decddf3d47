"""Crash safety: kill -9 during a recording then recovery; write errors (EFBIG) -> RecordingError."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from rosbags.highlevel import AnyReader

from ssi_bridge.exceptions import RecordingError
from ssi_bridge.record.reader import Bag
from ssi_bridge.record.recover import recover_bag

CHILD = Path(__file__).with_name("writer_child.py")


@pytest.fixture
def child(tmp_path: Path) -> Iterator[list[subprocess.Popen[str]]]:
    """Started children, always killed by PID at teardown, even when the test fails."""
    procs: list[subprocess.Popen[str]] = []
    yield procs
    for proc in procs:
        if proc.poll() is None:
            proc.kill()
        proc.wait(timeout=10)
        if proc.stdout:
            proc.stdout.close()


def start(procs: list[subprocess.Popen[str]], *args: str) -> subprocess.Popen[str]:
    proc = subprocess.Popen([sys.executable, str(CHILD), *args], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    procs.append(proc)
    return proc


def wait_for(proc: subprocess.Popen[str], prefix: str, timeout: float = 30.0,
             after: int = 0) -> list[str]:
    """Read lines until one starting with ``prefix`` (and, for 'wrote', count >= after)."""
    deadline = time.monotonic() + timeout
    assert proc.stdout is not None
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            pytest.fail(f"child exited ({proc.poll()}) before printing {prefix!r}")
        words = line.split()
        if words and words[0] == prefix and (prefix != "wrote" or int(words[1]) >= after):
            return words
    pytest.fail(f"child printed no {prefix!r} line within {timeout} s")


def test_kill_9_then_recover_loses_at_most_one_second(tmp_path: Path,
                                                      child: list[subprocess.Popen[str]]) -> None:
    bag = tmp_path / "crash"
    proc = start(child, str(bag))
    wait_for(proc, "wrote", after=2500)
    kill_ns = time.time_ns()
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=10)
    assert not (bag / "metadata.yaml").exists()
    with pytest.raises(RecordingError, match="recover"):
        Bag(bag)
    summary = recover_bag(bag)
    assert summary.message_count >= 1500
    with AnyReader([bag]) as reader:
        stamps = [t for _, t, _ in reader.messages()]
        assert len(stamps) == summary.message_count == reader.message_count
    assert stamps == sorted(stamps)
    assert kill_ns - stamps[-1] <= 1_000_000_000, f"lost {(kill_ns - stamps[-1]) / 1e9:.3f} s"
    with Bag(bag) as reopened:
        assert reopened.topics["/joint_states"].message_count == summary.message_count


def test_file_size_limit_is_a_recording_error_and_caller_goes_on(
        tmp_path: Path, child: list[subprocess.Popen[str]]) -> None:
    bag = tmp_path / "full"
    proc = start(child, str(bag), str(64 * 1024))
    words = wait_for(proc, "error")
    message = " ".join(words[1:])
    assert "File too large" in message and "errno 27" in message and "recording stopped" in message
    wait_for(proc, "published")
    assert proc.poll() is None, "the writer process must keep running after a write error"
    proc.kill()
    proc.wait(timeout=10)
    summary = recover_bag(bag)
    assert summary.message_count > 100
    with AnyReader([bag]) as reader:
        assert sum(1 for _ in reader.messages()) == summary.message_count


def test_recover_refuses_foreign_file(tmp_path: Path) -> None:
    bag = tmp_path / "foreign"
    bag.mkdir()
    (bag / "foreign_0.mcap").write_bytes(b"not an mcap file at all")
    with pytest.raises(RecordingError, match="not an MCAP file"):
        recover_bag(bag)
