"""What the kernel's scheduler did during the node's slowest 1 % of spans (``perf sched``).

    CYCLE_SPAN_DUMP=/tmp/spans.json perf sched record -k mono -o /tmp/ps.data -- \
        python bench/cycle_profile.py 8 8 --real --plain --span --span-frames --mt
    perf script -i /tmp/ps.data -F cpu,time,event,trace > /tmp/ps.txt
    python bench/cycle_sched.py /tmp/spans.json /tmp/ps.txt

For each of the slowest 1 % of spans (``bench/cycle_span.py``: the completing frame's kernel
receive time, its ``recv`` returning, ``publish()`` returned) it says where the time went:

* ``wake-up behind <task>``: the receive thread, blocked in ``recv``, was switched in more than
  150 us after its datagram came, the CPU it was woken on running ``<task>`` meanwhile (on a
  ``PREEMPT_NONE`` kernel a real-time wake-up waits until a task in a system call leaves the
  kernel);
* ``GIL wait``: it was switched in at once but slept again before ``recv`` returned: it waited
  for Python's lock; the node's threads that ran meanwhile (us) say who held it (little: the
  holder was itself off the CPU);
* ``behind``: ``recv`` returned late while the thread was running (an earlier frame's wait);
* ``handling``: the frame came in time; deciding and publishing took the span.

Times: perf's ``-k mono`` clock, the dump's ``realtime_minus_monotonic`` turns the spans' wall
clock times into it.
"""

from __future__ import annotations

import bisect
import collections
import json
import re
import sys

SWITCH = re.compile(r"\[(\d+)\]\s+([\d.]+):\s+sched:sched_switch:\s+prev_comm=(.*?) "
                    r"prev_pid=(\d+) prev_prio=(\d+) prev_state=(\S+) ==> next_comm=(.*?) "
                    r"next_pid=(\d+) next_prio=(\d+)")
WAKING = re.compile(r"\[(\d+)\]\s+([\d.]+):\s+sched:sched_waking:\s+comm=(.*?) pid=(\d+) "
                    r"prio=(\d+) target_cpu=(\d+)")
#: a wake-up or wait longer than this is counted as one (ns)
LATE_NS = 150_000


def main(dump: str, perf_text: str) -> int:
    """Print each slow span's cause and the counts (see the module docstring)."""
    data = json.load(open(dump))
    off = data["realtime_minus_monotonic"]
    names = {int(k): v for k, v in data.get("threads", {}).items()}
    spans = sorted(([a - off, b - off, c - off] for a, b, c in data["spans"]),
                   key=lambda s: s[2] - s[0])
    switches: list[tuple[int, int, int, str, str, int]] = []  # t, cpu, prev, state, next, pid
    wakes: dict[int, list[tuple[int, int]]] = collections.defaultdict(list)
    rx_seen: collections.Counter[int] = collections.Counter()
    with open(perf_text) as fh:
        for line in fh:
            if m := SWITCH.search(line):
                t = int(round(float(m[2]) * 1e9))
                switches.append((t, int(m[1]), int(m[4]), m[6], m[7], int(m[8])))
                if m[7] == "ssi_can_rx":
                    rx_seen[int(m[8])] += 1
            elif m := WAKING.search(line):
                wakes[int(m[4])].append((int(round(float(m[2]) * 1e9)), int(m[6])))
    if not rx_seen or not spans:
        print("no receive thread or no spans in the data")
        return 1
    rx_pid = rx_seen.most_common(1)[0][0]
    times = [s[0] for s in switches]
    running: dict[int, list[tuple[int, int]]] = collections.defaultdict(list)
    current: dict[int, tuple[int, int]] = {}
    for t, cpu, _prev, _state, _next, pid in switches:
        if cpu in current:
            running[current[cpu][1]].append((current[cpu][0], t))
        current[cpu] = (t, pid)

    def on_cpu(cpu: int, t: int) -> tuple[str, int] | None:
        i = bisect.bisect_right(times, t) - 1
        while i >= 0 and switches[i][1] != cpu:
            i -= 1
        return (switches[i][4], switches[i][5]) if i >= 0 else None

    causes: collections.Counter[str] = collections.Counter()
    for rx, returned, published in spans[int(len(spans) * 0.99):]:
        ins = [s for s in switches[bisect.bisect_left(times, rx):bisect.bisect_left(
            times, published)] if s[5] == rx_pid]
        outs = [s for s in switches[bisect.bisect_left(times, rx):bisect.bisect_left(
            times, returned)] if s[2] == rx_pid and s[3].startswith("S")]
        was_on = any((on_cpu(c, rx) or ("", -1))[1] == rx_pid for c in (0, 1))
        wake = returned - rx
        woken = (ins[0][0] - rx) if ins and not was_on else 0
        ours: collections.Counter[str] = collections.Counter()
        for pid, name in names.items():
            if pid != rx_pid:
                for a, b in running.get(pid, []):
                    if b > rx and a < returned:
                        ours[name] += min(b, returned) - max(a, rx)
        held = ", ".join(f"{n} {v / 1e3:.0f}" for n, v in ours.most_common(3))
        if woken > LATE_NS:
            k = bisect.bisect_right([w[0] for w in wakes[rx_pid]], rx) - 1
            cpu = wakes[rx_pid][k][1] if k >= 0 else 0
            task = (on_cpu(cpu, ins[0][0] - 1) or ("?", 0))[0]
            kind = "wake-up behind " + ("an idle CPU's exit" if task.startswith("swapper")
                                        else "another task")
            what = f"{kind} ({task}, {woken / 1e3:.0f} us)"
        elif outs and wake > LATE_NS:
            kind = "GIL wait"
            what = f"GIL wait {wake / 1e3:.0f} us (the node's threads meanwhile, us: {held})"
        elif wake > LATE_NS:
            kind, what = "behind", f"recv returned {wake / 1e3:.0f} us late while running"
        else:
            kind, what = "handling", "deciding and publishing"
        causes[kind] += 1
        print(f"span {(published - rx) / 1e3:6.0f} us: {what}")
    print(dict(causes))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2]))
