"""Child process of the crash and disk-full tests: record JointState at 1 kHz until killed.

Usage: ``writer_child.py BAG [FSIZE_LIMIT_BYTES]``. Prints ``wrote <n> <log_time_ns>`` lines
(every 50 messages) so the parent knows how far it got; with a file-size limit (RLIMIT_FSIZE,
SIGXFSZ ignored) the writes fail with EFBIG, and it prints ``error <message>`` and goes on
"publishing" (counting cycles) to show that a recording error does not stop the caller.
"""

from __future__ import annotations

import resource
import signal
import sys
import time
from pathlib import Path

from sensor_msgs.msg import JointState

from ssi_bridge.exceptions import RecordingError
from ssi_bridge.record.bag import BagRecorder


def main() -> None:
    bag = Path(sys.argv[1])
    if len(sys.argv) > 2:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        limit = int(sys.argv[2])
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    rec = BagRecorder.open(bag, compression="none" if len(sys.argv) > 2 else "zstd")
    rec.add_topic("/joint_states", "sensor_msgs/msg/JointState")
    recording, published, i = True, 0, 0
    next_t = time.monotonic()
    while True:
        now = time.time_ns()
        msg = JointState(name=["axis_1"], position=[i * 1e-3], velocity=[1.0])
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(now, 1_000_000_000)
        published += 1
        if recording:
            try:
                rec.write("/joint_states", msg, now)
            except RecordingError as err:
                recording = False
                print(f"error {err}", flush=True)
        elif published % 200 == 0:
            print(f"published {published}", flush=True)
        i += 1
        if recording and i % 50 == 0:
            print(f"wrote {i} {now}", flush=True)
        next_t += 1e-3
        time.sleep(max(0.0, next_t - time.monotonic()))


if __name__ == "__main__":
    main()
