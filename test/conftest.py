"""Fixtures shared by every test folder."""

from __future__ import annotations

import ctypes
import fcntl
import os
import random
import signal
import subprocess
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

#: DDS domain ids a test may take (Fast DDS's default port mapping allows 0-232; 0 is left to
#: users). Claims are flock()ed files, so parallel test runs on one machine never share one.
DOMAIN_IDS = range(1, 233)
CLAIMS = Path(os.environ.get("TMPDIR", "/tmp")) / "ssi_bridge_test_domains"
#: prctl(2) option: the signal a child gets when the thread that started it ends
PR_SET_PDEATHSIG = 1
_prctl = ctypes.CDLL(None, use_errno=True).prctl  # resolved before any fork


def dies_with_this_process() -> Callable[[], None]:
    """A ``preexec_fn`` that makes the child die with the calling (test) process.

    PR_SET_PDEATHSIG sends SIGKILL to the child when the thread that forked it ends (pytest
    starts children from its main thread), so a killed test run leaves no node behind. SIGINT
    is set back to its default: a background job of a non-interactive shell starts with SIGINT
    ignored, Python keeps it so, and a test that stops its child with SIGINT needs it handled.
    """
    parent = os.getpid()

    def preexec() -> None:
        signal.signal(signal.SIGINT, signal.SIG_DFL)
        _prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        if os.getppid() != parent:
            os._exit(1)  # the parent died before prctl took effect

    preexec.dies_with_parent = True  # type: ignore[attr-defined]
    return preexec


@pytest.fixture
def child_preexec() -> Callable[[], None]:
    """The ``preexec_fn`` a test passes to Popen/run: see :func:`dies_with_this_process`."""
    return dies_with_this_process()


@pytest.fixture(autouse=True)
def _children_die_with_the_test(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every process a test starts (Popen, subprocess.run) dies with the test process: its
    ``preexec_fn`` runs :func:`dies_with_this_process`'s first, then the test's own."""
    original = subprocess.Popen.__init__

    def init(self: subprocess.Popen, *args: Any, **kwargs: Any) -> None:
        own = kwargs.get("preexec_fn")
        if not getattr(own, "dies_with_parent", False):
            first = dies_with_this_process()

            def both() -> None:
                first()
                if own is not None:
                    own()

            kwargs["preexec_fn"] = both
        original(self, *args, **kwargs)

    monkeypatch.setattr(subprocess.Popen, "__init__", init)


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


@contextmanager
def held_domain() -> Iterator[int]:
    """A DDS domain id no other running test holds (:func:`claim_domain`), released on exit."""
    dom, fd = claim_domain()
    try:
        yield dom
    finally:
        os.close(fd)


@pytest.fixture
def ros_domain() -> Iterator[int]:
    """A test-unique ROS_DOMAIN_ID, held until the test ends."""
    with held_domain() as dom:
        yield dom


@pytest.fixture(scope="module")
def module_domain() -> Iterator[int]:
    """A ROS_DOMAIN_ID held for a whole test module (the node and probe its tests share)."""
    with held_domain() as dom:
        yield dom


@pytest.fixture(scope="module")
def module_child_preexec() -> Callable[[], None]:
    """:func:`child_preexec` for a process that lives as long as the test module."""
    return dies_with_this_process()


@pytest.fixture
def small_fs(tmp_path: Path) -> Iterator[Callable[[int], Path]]:
    """Factory: a tmpfs of ``size`` bytes mounted under tmp_path (root only), unmounted after.

    A real file system that runs full (ENOSPC), for the write-error paths of the recorders.
    """
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


# -- bags in log-time order ------------------------------------------------------------------
def log_time_disorder(root: Path) -> list[str]:
    """Messages of the MCAP files under ``root`` (a file or a directory) logged before the
    message before them in the same file, any topic (``~/events`` too): ``mcap doctor
    --strict-message-order``'s rule, read in file order with mcap's stream reader. One line
    per message out of order; a file cut short (a crash test's) or not MCAP at all (a test of
    the readers' refusals) is checked as far as it reads.
    """
    import struct

    from mcap.exceptions import McapError
    from mcap.records import Channel, Message
    from mcap.stream_reader import StreamReader

    files = [root] if root.is_file() else sorted(root.rglob("*.mcap"))
    out = []
    for path in files:
        topics: dict[int, str] = {}
        last: tuple[int, str] | None = None
        with open(path, "rb") as f:
            try:
                for record in StreamReader(f).records:
                    if isinstance(record, Channel):
                        topics[record.id] = record.topic
                    elif isinstance(record, Message):
                        topic = topics.get(record.channel_id, f"channel {record.channel_id}")
                        if last is not None and record.log_time < last[0]:
                            out.append(f"{path}: {topic} logged at {record.log_time}, "
                                       f"{(last[0] - record.log_time) / 1e6:.3f} ms before "
                                       f"the {last[1]} message before it")
                        last = (record.log_time, topic)
            except (McapError, EOFError, struct.error):
                pass  # cut short or foreign: what was read is checked
    return out


@pytest.fixture(autouse=True)
def _bags_in_log_time_order(request: pytest.FixtureRequest) -> Iterator[None]:
    """After every test with a ``tmp_path``: each bag it wrote there (a node's sessions and
    snapshots, the recorder's own) has its messages in non-decreasing log time per file."""
    tmp = request.getfixturevalue("tmp_path") if "tmp_path" in request.fixturenames else None
    yield
    if tmp is not None and tmp.exists():
        disorder = log_time_disorder(tmp)
        assert not disorder, "messages out of log-time order:\n" + "\n".join(disorder[:10])


# -- test tiers: the markers come from here, not from each file ------------------------------
#: markers only this file sets; a test or module that sets one by hand stops the collection
TIER_MARKERS = frozenset({"node", "slow", "smoke", "load", "integration"})
#: a test with a DDS domain of its own starts a ROS node as a subprocess (the bridge, the
#: managed node or a ROS tool) and talks to it: ``node``
NODE_FIXTURES = frozenset({"ros_domain", "module_domain"})
#: load, stress, soak and two-host tests: ``slow``, left out of ``make test``, run by
#: ``make test-all``. A file names all its tests, ``file::test`` every case of that test.
#: An entry whose reason starts with ``load:`` (the node beside CPU burners) is also ``load``.
SLOW = {
    "test/ros/test_node_truth_matrix.py::test_the_disturbance_matrix_on_two_stations_beside_two_burners":
        "load: the disturbance matrix beside two CPU burners, held to the truth",
    "test/ros/test_node_truth_matrix.py::test_the_disturbance_matrix_on_eight_joints":
        "soak: the disturbance matrix on eight joints, held to the truth",
    "test/ros/test_node_truth_matrix.py::test_a_station_killed_and_started_again_on_the_same_bus":
        "stress: a station killed and another started on the same bus",
    "test/ros/test_node_truth_matrix.py::test_a_burst_of_1000_service_calls_during_motion":
        "stress: 1000 service calls at once during motion, held to the truth",
    "test/ros/test_node_load.py": "load: 60 s at 1 kHz beside two CPU burners",
    "test/ros/test_node_two_hosts.py": "two hosts: three network namespaces",
    "test/ros/test_node_stop.py::"
    "test_can_log_write_error_is_an_error_at_once_and_everything_stays_clean":
        "soak: a 4 MB CAN log filled at 1 kHz, then 30 s of RSS watched",
    "test/ros/test_node_stop.py::"
    "test_double_sigint_10ms_apart_while_recording_exits_0_with_a_whole_bag":
        "stress: 20 starts, each stopped by two SIGINTs",
    "test/ros/test_node_stop.py::test_stop_signals_at_any_moment_of_start_up_and_shutdown":
        "stress: 15 starts, each hit by a burst of signals",
    "test/sim/supervisor/test_station_process.py::test_station_survives_a_storm_of_stop_signals":
        "stress: 6 stations, 400 signals each",
    "test/ros/test_node_services.py::"
    "test_a_burst_of_1000_calls_from_4_clients_is_answered_in_full":
        "stress: 1000 service calls at once",
    "test/ros/test_node_snapshot.py::test_memory_stays_bounded_with_snapshots_over_ten_minutes":
        "soak: 10 minutes at 500 Hz with fault snapshots, RSS watched",
    "test/commission/test_stations.py::test_random_stations_sweep":
        "sweep: ten random stations of 1-8 joints commissioned, about 5 s each",
}
#: node tests that check the install path (the installed executables start and answer), not
#: the logic again: .ci/run's workspace step runs only these (``-m smoke``)
SMOKE = {
    "test/ros/test_node_skeleton.py::test_register_services_over_the_handshake",
    "test/ros/test_node_skeleton.py::"
    "test_joint_states_rate_name_stamps_and_speed_and_diagnostics_ok_for_the_joint",
    "test/ros/test_node_lifecycle.py::test_walk_through_the_lifecycle",
    "test/ros/test_node_station_process.py::"
    "test_node_with_simulation_false_drives_a_separately_started_station",
    "test/ros/test_monitor.py::test_monitor_prints_the_running_bridge_and_stops_cleanly_on_ctrl_c",
}
#: pytest-timeout (s) of a slow test; every other test has setup.cfg's ``timeout``
SLOW_TIMEOUT = 600


def _listed(item: pytest.Item, names: dict[str, str] | set[str]) -> bool:
    test = item.nodeid.split("[")[0]
    return test in names or test.split("::")[0] in names


def _check_lists(root: Path) -> None:
    """Every SLOW and SMOKE entry names a test that exists (a renamed test would otherwise
    fall silently out of its tier)."""
    for entry in (*SLOW, *SMOKE):
        path, _, name = entry.partition("::")
        source = root / path
        if not source.is_file() or (name and f"def {name}(" not in source.read_text()):
            raise pytest.UsageError(f"test/conftest.py lists {entry}, which does not exist")


def _reason(item: pytest.Item, names: dict[str, str]) -> str:
    test = item.nodeid.split("[")[0]
    return names.get(test) or names.get(test.split("::")[0], "")


def _check_hand_set(items: list[pytest.Item]) -> None:
    """No test, class or module sets a tier marker itself: they come from this file only."""
    by_hand = sorted({f"{item.nodeid.split('[')[0]}: {mark.name}" for item in items
                      for mark in item.iter_markers() if mark.name in TIER_MARKERS})
    if by_hand:
        raise pytest.UsageError("tier markers are set by test/conftest.py, not by hand "
                                "(node: by fixture; slow, smoke, load: its lists): "
                                + "; ".join(by_hand))


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    _check_lists(Path(_REPO))
    _check_hand_set(items)
    for item in items:
        if NODE_FIXTURES & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.node)
        if _listed(item, SMOKE):
            item.add_marker(pytest.mark.smoke)
        if _listed(item, SLOW):
            item.add_marker(pytest.mark.slow)
            if _reason(item, SLOW).startswith("load:"):
                item.add_marker(pytest.mark.load)
            if item.get_closest_marker("timeout") is None:
                item.add_marker(pytest.mark.timeout(SLOW_TIMEOUT))


# -- no orphans: a process of this repository that outlived its parent is a defect ----------
#: how long (s) the end of the session waits for orphans that are still stopping
ORPHAN_GRACE_S = 5.0
_REPO = str(Path(__file__).resolve().parent.parent)
_SESSION_START_TICKS: list[int] = []


def _start_ticks(pid: int) -> int:
    """A process's start time in clock ticks since boot (/proc/<pid>/stat field 22)."""
    with open(f"/proc/{pid}/stat", encoding="ascii", errors="replace") as f:
        return int(f.read().rpartition(")")[2].split()[19])


def _orphans() -> list[tuple[int, str]]:
    """Processes of this checkout (their command line names it) started during this session
    whose parent is gone (re-parented to init)."""
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        pid = int(entry)
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                cmd = f.read().replace(b"\0", b" ").decode(errors="replace").strip()
            if _REPO not in cmd or pid == os.getpid():
                continue
            with open(f"/proc/{pid}/status", encoding="ascii", errors="replace") as f:
                ppid = next(int(ln.split()[1]) for ln in f if ln.startswith("PPid:"))
            if ppid == 1 and _start_ticks(pid) >= _SESSION_START_TICKS[0]:
                found.append((pid, cmd))
        except (OSError, StopIteration, ValueError, IndexError):
            continue  # ended meanwhile
    return found


def pytest_sessionstart(session: pytest.Session) -> None:
    _SESSION_START_TICKS.append(_start_ticks(os.getpid()))


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    """Fail the run if a node, station or tool a test started outlived its parent (a child
    must die with its node; a test must stop what it starts); kill them after reporting."""
    if not _SESSION_START_TICKS or not os.path.isdir("/proc"):
        return
    deadline = time.monotonic() + ORPHAN_GRACE_S
    orphans = _orphans()
    while orphans and time.monotonic() < deadline:
        time.sleep(0.2)
        orphans = _orphans()
    if not orphans:
        return
    reporter = session.config.pluginmanager.get_plugin("terminalreporter")
    if reporter is not None:
        reporter.write_line("")
        reporter.write_sep("=", "processes that outlived their parent: the run fails", red=True)
    for pid, cmd in orphans:
        line = f"orphan process {pid} (parent gone) outlived the session: {cmd[:300]}"
        if reporter is not None:
            reporter.write_line(line, red=True)
        try:
            os.kill(pid, signal.SIGKILL)
        except OSError:
            pass
    session.exitstatus = pytest.ExitCode.TESTS_FAILED
