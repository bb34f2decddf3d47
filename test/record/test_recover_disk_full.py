"""``replay --recover`` on a full disk: exit 2 with a message, nothing written, bag unchanged.

The disk is a real tmpfs of a few hundred kB (root only), filled up to ENOSPC.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

from sensor_msgs.msg import JointState

from ssi_bridge.record.bag import BagRecorder
from ssi_bridge.record.reader import Bag


def crashed_bag(tmp_path: Path, messages: int = 2000) -> Path:
    """A bag whose writer flushed its chunks but never wrote the summary (like kill -9)."""
    bag_dir = tmp_path / "crashed"
    bag = BagRecorder.open(bag_dir, compression="none")
    bag.add_topic("/joint_states", "sensor_msgs/msg/JointState")
    for i in range(messages):
        msg = JointState(name=["axis_1"], position=[0.001 * i], velocity=[1.0])
        bag.write("/joint_states", msg, log_time_ns=1_000_000 * (i + 1))
    bag.flush()
    return bag_dir


def recover(bag: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "ssi_bridge.tools.replay", "--recover",
                           str(bag)], capture_output=True, text=True, timeout=120)


def test_recover_on_a_full_disk_exits_2_and_writes_nothing(tmp_path: Path, small_fs) -> None:
    source = crashed_bag(tmp_path)
    mcap = next(source.glob("*.mcap"))
    fs = small_fs(2 * mcap.stat().st_size + 256 * 1024)
    bag = fs / "crashed"
    bag.mkdir()
    shutil.copy(mcap, bag / mcap.name)
    before = (bag / mcap.name).read_bytes()
    filler = small_fs.fill(fs)

    out = recover(bag)
    assert out.returncode == 2, out.stderr
    assert "Traceback" not in out.stderr
    assert "replay: error:" in out.stderr and "errno 28" in out.stderr, out.stderr
    assert sorted(p.name for p in bag.iterdir()) == [mcap.name], "no partial file left behind"
    assert (bag / mcap.name).read_bytes() == before, "the bag is as it was"

    filler.unlink()  # with space again the same bag recovers
    out = recover(bag)
    assert out.returncode == 0, out.stderr
    with Bag(bag) as done:
        assert done.topics["/joint_states"].message_count == 2000
