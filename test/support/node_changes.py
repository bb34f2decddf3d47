"""The node held to the truth while a caller changes it: settings written during motion,
service bursts, lifecycle transitions.

A setting that moves the zero point or the scale (REG_PARA1, REG_OFFSET, a preset) changes
the truth itself at the moment the module takes it. :class:`Change` records when a call
started and returned (wire time, ``time.time()``) and the oracle of the settings after it;
:func:`hold_changes` holds the samples stamped before the first call against the run's
oracle, those between two calls against the oracle of the change before them, and those
stamped while a call was under way against either side (or NaN). Test-side only.
"""

from __future__ import annotations

import math
import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from rclpy.qos import HistoryPolicy, QoSProfile
from ssi_bridge_msgs.srv import ReadRegister

from support.node_truth import Run
from support.truth import Sample, TruthOracle


@dataclass(frozen=True)
class Change:
    """One call that changed the truth: it started at ``w0`` and returned at ``w1`` (wire
    time); ``oracle`` is the truth after it."""

    name: str
    w0: float
    w1: float
    oracle: TruthOracle


def timed(run: Run, name: str, call: Callable[[], Any],
          oracle_of: Callable[[Any], TruthOracle]) -> tuple[Change, Any]:
    """Run ``call`` as the disturbance ``name`` of ``run`` (:meth:`Run.phase`) and return
    the :class:`Change` it made (``oracle_of`` its result gives the truth after it) and the
    result."""
    run.phase(name)
    w0 = time.time()
    result = call()
    w1 = time.time()
    return Change(name, w0, w1, oracle_of(result)), result


def set_integer(probe: Any, node: Any, name: str, value: int) -> None:
    """Set an integer parameter of the node; a refusal fails the test."""
    res = probe.call(SetParameters, node.topic("~/set_parameters"), SetParameters.Request(
        parameters=[Parameter(name=name, value=ParameterValue(
            type=ParameterType.PARAMETER_INTEGER, integer_value=value))]), timeout=30.0)
    assert res.results[0].successful, res.results[0].reason


def hold_changes(run: Run, changes: list[Change], case: str, t0: float) -> None:
    """Every sample received so far holds the rule against the truth of its stamp's side of
    ``changes`` (in call order); a sample stamped while a call was under way holds it
    against the side before or after that call, position only (NaN is unknown, never
    wrong). Samples are taken once the run has received all stamped until now
    (``run.received_until``). A failure names the segment."""
    run.received_until(time.time())
    samples = run.samples()
    oracles = [run.oracle] + [c.oracle for c in changes]
    edges = [-math.inf] + [x for c in changes for x in (c.w0, c.w1)] + [math.inf]
    for k, oracle in enumerate(oracles):
        lo, hi = edges[2 * k], edges[2 * k + 1]
        segment = [s for s in samples if lo < s.stamp < hi]
        label = "before any change" if k == 0 else f"after {changes[k - 1].name}"
        assert segment, f"{case}: no sample stamped {label}" + _why_none(run, lo, hi)
        try:
            run.hold(segment, oracle, f"{case}: {label}" if k else case, t0)
        except AssertionError as err:
            raise AssertionError(f"{case}, samples stamped {label}: {err}") from None
    for k, change in enumerate(changes):
        during = [s for s in samples if change.w0 <= s.stamp <= change.w1]
        off = [(s, oracles[k].residual(s.joint, s.stamp, s.position),
                oracles[k + 1].residual(s.joint, s.stamp, s.position))
               for s in during if not _either(s, oracles[k], oracles[k + 1], run.bound)]
        assert not off, (f"{case}: {len(off)} samples stamped during {change.name} off both "
                         f"truths (residuals before/after, counts): "
                         + ", ".join(f"{s.stamp:.4f} {a:+.0f}/{b:+.0f}" for s, a, b in off[:5]))


def _why_none(run: Run, lo: float, hi: float) -> str:
    """What the node's ~/status said of the first joint in the cycles stamped in (lo, hi):
    how many it left out and why, so an empty segment names its cause ("" for a run without
    ~/status, the in-process one)."""
    if not hasattr(run, "status"):
        return ""

    def stamp(m: Any) -> float:
        return m.header.stamp.sec + m.header.stamp.nanosec * 1e-9

    cycles = [(stamp(m), ch) for _, m in run.status if lo < stamp(m) < hi
              for ch in m.channels if ch.joint == run.first]
    reasons = Counter(ch.set_aside_reason or "published" for _, ch in cycles)
    span = f"{hi - lo:.3f} s" if math.isfinite(hi - lo) else "open"
    newest = max((stamp(m) for _, m in run.status), default=math.nan)
    return (f" (segment {span}; ~/status of {run.first} in it: {len(cycles)} cycles, "
            f"{dict(reasons)}; the newest ~/status received is stamped "
            f"{time.time() - newest:.3f} s ago)")


def _either(s: Sample, before: TruthOracle, after: TruthOracle, bound_s: float) -> bool:
    if not math.isfinite(s.position):
        return True
    return any(abs(o.residual(s.joint, s.stamp, s.position)) <= o.position_bound(s.joint, bound_s)
               for o in (before, after))


def read_burst(probe: Any, node: Any, calls: int, clients: int, timeout: float,
               joint: str = "") -> tuple[Counter[str], float]:
    """``calls`` ``~/read_register`` calls (REG_PARA1) sent at once from ``clients`` threads,
    each with a client of its own that keeps every request (KEEP_ALL, docs/node.md
    "Services"). Returns the outcomes ("ok", "busy", "refused: <message>", "unanswered")
    and the seconds until the last answer."""
    outcomes: Counter[str] = Counter()
    lock = threading.Lock()
    qos = QoSProfile(history=HistoryPolicy.KEEP_ALL)
    made = [probe.node.create_client(ReadRegister, node.topic("~/read_register"),
                                     qos_profile=qos) for _ in range(clients)]
    done = threading.Semaphore(0)
    start = time.monotonic()
    last = [start]

    def answered(future: Any) -> None:
        res = future.result()
        key = ("ok" if res.success else "busy" if "busy" in res.message
               else f"refused: {res.message[:80]}")
        with lock:
            outcomes[key] += 1
            last[0] = time.monotonic()
        done.release()

    def send(client: Any, n: int) -> None:
        for _ in range(n):
            client.call_async(ReadRegister.Request(joint=joint, address=20)
                              ).add_done_callback(answered)

    try:
        for client in made:
            assert client.wait_for_service(timeout_sec=10.0), "~/read_register not available"
        threads = [threading.Thread(target=send, args=(c, calls // clients)) for c in made]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        deadline = start + timeout
        for _ in range(clients * (calls // clients)):
            if not done.acquire(timeout=max(0.0, deadline - time.monotonic())):
                break
        with lock:
            outcomes["unanswered"] = clients * (calls // clients) - sum(outcomes.values())
            return outcomes, last[0] - start
    finally:
        for client in made:
            probe.node.destroy_client(client)


def published(run: Run, w0: float, w1: float) -> tuple[float, float]:
    """The rate (samples/s) at which the node published the first joint in [w0, w1] (wire
    time), by the ``samples`` count of its ``~/status`` channel (what the node published,
    whether or not this probe received it all: a starved probe loses messages beyond the
    publisher's history), and the longest time (s) without a joint_states message this
    probe received."""
    def stamp(m: Any) -> float:
        return m.header.stamp.sec + m.header.stamp.nanosec * 1e-9

    counts = sorted((stamp(m), ch.samples) for _, m in run.status if w0 <= stamp(m) <= w1
                    for ch in m.channels if ch.joint == run.first)
    assert len(counts) >= 2, f"no ~/status in [{w0:.3f}, {w1:.3f}]"
    (a, na), (b, nb) = counts[0], counts[-1]
    edges = [w0] + sorted(s for _, m in run.joints if w0 <= (s := stamp(m)) <= w1) + [w1]
    return (nb - na) / (b - a), float(max(y - x for x, y in zip(edges, edges[1:])))
