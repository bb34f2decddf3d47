"""Child process of the split crash test: record JointState at 1 kHz, split every N s, until
killed.

Usage: ``split_writer_child.py BAG MAX_DURATION_S``. After each flush of the recorder (the
background thread's, every 0.5 s) it prints ``file <k> <n>``: the open file's index and the
messages written so far; a file is opened by a message, so after ``file 2`` the third file
has data on disk.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from sensor_msgs.msg import JointState

from ssi_bridge.record.bag import BagRecorder


def main() -> None:
    bag, max_duration = Path(sys.argv[1]), float(sys.argv[2])
    rec = BagRecorder.open(bag, max_duration_s=max_duration, flush_period_s=0.2)
    rec.add_topic("/joint_states", "sensor_msgs/msg/JointState")
    i = 0
    next_t = time.monotonic()
    next_report = next_t + 0.5
    while True:
        now = time.time_ns()
        msg = JointState(name=["axis_1"], position=[i * 1e-3], velocity=[1.0])
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(now, 1_000_000_000)
        rec.write("/joint_states", msg, now)
        i += 1
        if time.monotonic() >= next_report:
            rec.flush()     # on disk now, whatever the flush thread's phase
            files = rec.files
            print(f"file {len(files) - 1} {rec.message_count}", flush=True)
            next_report += 0.5
        next_t += 1e-3
        time.sleep(max(0.0, next_t - time.monotonic()))


if __name__ == "__main__":
    main()
