"""replay with the player's controls: each option and each control, the played messages counted
and timed, against an rclpy subscriber in this process (replay runs as its own process).

Options: --playback-duration, --playback-until (seconds from the start and a ROS sec.nsec),
--exclude-topics, --regex, --exclude-regex, the default wait for subscribers (#24 item 7).
--exclude-topics naming a topic the bag lacks excludes nothing and is no error, as in
``ros2 bag play`` (rosbag2's storage filter only asks whether a recorded topic is listed).
Ctrl-C (SIGINT) and SIGTERM stop the replay with exit 0, as ``ros2 bag play`` does.
Controls: the services ~/pause ~/resume ~/play_next ~/set_rate ~/seek, and the keys through
a pseudo-terminal (space, →, ↑, ↓) with the progress line read back from it.
"""

from __future__ import annotations

import fcntl
import os
import re
import select
import signal
import subprocess
import sys
import termios
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

from support import waiting

from .conftest import T0, joint_states_bag

PERIOD_NS = 10_000_000   # 100 Hz
MS = 1_000_000
RELIABLE = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
ARM, BASE = "/arm/joint_states", "/base/joint_states"


@pytest.fixture(scope="module")
def one_s(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return joint_states_bag(tmp_path_factory.mktemp("ctl") / "one_s", 100, period_ns=PERIOD_NS)


@pytest.fixture(scope="module")
def two_topics(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return joint_states_bag(tmp_path_factory.mktemp("ctl") / "two", 30, (ARM, BASE), PERIOD_NS)


@pytest.fixture(scope="module")
def four_s(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return joint_states_bag(tmp_path_factory.mktemp("ctl") / "four_s", 400, period_ns=PERIOD_NS)


def index(msg: JointState) -> int:
    """Which recorded message this is (joint_state(i) has position 0.001 i)."""
    return round(msg.position[0] * 1000)


class Probe:
    """Subscriptions and service calls in this process, spun by a thread."""

    def __init__(self, context: Context) -> None:
        self.context = context
        self.node = rclpy.create_node("replay_probe", context=context)
        self.got: dict[str, list[tuple[float, JointState]]] = {}
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        while not self._stop.is_set():
            self.executor.spin_once(0.01)

    def subscribe(self, topic: str) -> list[tuple[float, JointState]]:
        """Messages on ``topic`` with the time the replay published each (seconds).

        The time is the DDS source timestamp the writer puts on each sample, not this
        process's receive time: a probe starved on a busy machine takes a burst of samples at
        once, and the replay's pace is what the tests check.

        Each call starts a new list (one subscription per topic, kept): a test that runs the
        replay twice counts each run's messages apart.
        """
        rx: list[tuple[float, JointState]] = []
        fresh = topic not in self.got
        self.got[topic] = rx

        def take(msg: JointState, info: dict[str, int]) -> None:
            self.got[topic].append((info["source_timestamp"] / 1e9, msg))

        if fresh:
            self.node.create_subscription(JointState, topic, take, RELIABLE)
        return rx

    def call(self, srv_type: Any, name: str, request: Any, timeout: float = 20.0) -> Any:
        client = self.node.create_client(srv_type, name)
        assert client.wait_for_service(timeout), f"service {name} not there"
        future = client.call_async(request)
        deadline = time.monotonic() + timeout
        while not future.done():
            assert time.monotonic() < deadline, f"{name}: no answer"
            time.sleep(0.01)
        return future.result()

    def close(self) -> None:
        self._stop.set()
        self._thread.join()
        self.executor.shutdown()
        self.node.destroy_node()


@pytest.fixture
def probe(monkeypatch: pytest.MonkeyPatch, ros_domain: int) -> Iterator[Probe]:
    monkeypatch.setenv("ROS_DOMAIN_ID", str(ros_domain))
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    context = Context()
    rclpy.init(context=context)
    probe = Probe(context)
    yield probe
    probe.close()
    rclpy.try_shutdown(context=context)


def command(bag: Path, *args: str) -> list[str]:
    return [sys.executable, "-m", "ssi_bridge.tools.replay", str(bag), *args]


def run(bag: Path, *args: str) -> subprocess.CompletedProcess[str]:
    out = subprocess.run(command(bag, *args), capture_output=True, text=True, timeout=90,
                         env=dict(os.environ), check=False)
    assert out.returncode == 0, out.stderr
    return out


def wait_for(cond: Callable[[], bool], timeout: float, what: str) -> None:
    """:func:`support.waiting.wait_for`, polling every 10 ms, failing with
    "timed out waiting for ``what``"."""
    waiting.wait_for(cond, f"timed out waiting for {what}", timeout, poll=0.01)


def settle(rx: list, quiet: float = 0.5, timeout: float = 10.0) -> None:
    """Wait until nothing more arrives for ``quiet`` seconds."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        n = len(rx)
        time.sleep(quiet)
        if len(rx) == n:
            return


# -- options ---------------------------------------------------------------------------------

def _played(first: int, last: int) -> tuple[dict[str, list[int]], tuple[float, float]]:
    """One topic, /joint_states, played from message ``first`` to ``last``; its span bounds."""
    expected = (last - first) * PERIOD_NS / 1e9
    return {"/joint_states": list(range(first, last + 1))}, (0.6 * expected, expected + 0.5)


#: two topics: which of them played (all 30 messages each); 29 periods of 10 ms
_BOTH = (0.15, 1.0)


@pytest.mark.parametrize(("bag", "args", "played", "span"), [
    ("one_s", ["--playback-duration", "0.5"], *_played(0, 50)),
    ("one_s", ["--start-offset", "0.2", "--playback-duration", "0.3"], *_played(20, 50)),
    ("one_s", ["--playback-until", "0.305"], *_played(0, 30)),
    ("one_s", ["--playback-until", f"{T0 // 10**9}.{(T0 + 255 * MS) % 10**9:09d}"],
     *_played(0, 25)),
    ("one_s", ["--playback-until-nsec", str(T0 + 700 * MS)], *_played(0, 70)),
    ("two_topics", ["--exclude-topics", BASE], {ARM: list(range(30)), BASE: []}, _BOTH),
    ("two_topics", ["--exclude-topics", BASE, "/not_in_the_bag"],
     {ARM: list(range(30)), BASE: []}, _BOTH),
    ("two_topics", ["--exclude-topics", "/not_in_the_bag"],
     {ARM: list(range(30)), BASE: list(range(30))}, _BOTH),
    ("two_topics", ["--regex", "^/base/"], {ARM: [], BASE: list(range(30))}, _BOTH),
    ("two_topics", ["--topics-regex", "joint_states$", "--exclude-regex", "arm"],
     {ARM: [], BASE: list(range(30))}, _BOTH),
    ("two_topics", ["--topics", ARM, "--exclude-regex", "base"],
     {ARM: list(range(30)), BASE: []}, _BOTH),
], ids=["duration", "offset_duration", "until_seconds", "until_sec_nsec", "until_nsec",
        "exclude_topic", "exclude_topic_and_unknown", "exclude_unknown_only", "regex",
        "regex_and_exclude_regex", "topics_and_exclude_regex"])
def test_the_selection_options_play_exactly_the_selected_messages(
        request: pytest.FixtureRequest, probe: Probe, bag: str, args: list[str],
        played: dict[str, list[int]], span: tuple[float, float]) -> None:
    """The end time (--playback-duration, --playback-until[-nsec]: the message at or before
    it is the last) and the topic selection (--exclude-topics, --regex, --exclude-regex):
    which messages each topic gets, in order, at the bag's pace. (Two functions before, the
    end-time cases and the topic cases.)"""
    rx = {topic: probe.subscribe(topic) for topic in played}
    run(request.getfixturevalue(bag), "--wait-for-subscribers", "20", "--quiet", *args)
    settle(next(rx[t] for t, want in played.items() if want))
    assert {t: len(got) for t, got in rx.items()} == {t: len(w) for t, w in played.items()}
    assert {t: [index(m) for _, m in got] for t, got in rx.items()} == played
    some = next(got for got in rx.values() if got)
    lo, hi = span
    assert lo < some[-1][0] - some[0][0] < hi, (some[-1][0] - some[0][0], span)


def test_a_selection_of_nothing_or_an_unknown_topic_is_refused(two_topics: Path) -> None:
    for args, match in ((["--exclude-regex", "joint"], "leaves nothing to play"),
                        (["--topics", "/nope"], "no topic /nope"),
                        (["--regex", "("], "regular expression"),
                        (["--playback-until", "soon"], "invalid seconds value")):
        out = subprocess.run(command(two_topics, *args), capture_output=True, text=True,
                             timeout=60, check=False)
        assert out.returncode == 2 and match in out.stderr, (args, out.stderr)


def test_the_wait_for_subscribers_5_s_by_default_0_off_and_a_subscriber_gets_the_first(
        one_s: Path, probe: Probe) -> None:
    """#24 item 7: replay waits for subscribers by default (5 s), so none loses the start;
    without one it plays anyway after 5 s; 0 turns the wait off. (Two functions before: the
    runs without a subscriber first, then with the probe's.)"""
    began = time.monotonic()
    waited = run(one_s, "--quiet", "--playback-duration", "0.05")
    assert "no subscriber on /joint_states after 5.0 s; playing anyway" in waited.stderr
    assert time.monotonic() - began > 5.0
    off = run(one_s, "--playback-duration", "0.05", "--wait-for-subscribers", "0")
    assert "playing anyway" not in off.stderr and "replayed 6 messages" in off.stdout
    assert "[R]" not in off.stderr and "\r" not in off.stderr, "no progress line off a terminal"

    rx = probe.subscribe("/joint_states")
    out = run(one_s, "--quiet")
    settle(rx)
    assert [index(m) for _, m in rx] == list(range(100)), out.stderr
    assert "playing anyway" not in out.stderr


def _foxglove_view_and_ros_publishing_together(one_s: Path, probe: Probe) -> None:
    import socket
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    rx = probe.subscribe("/joint_states")
    proc = subprocess.Popen(command(one_s, "--quiet", "--foxglove-port", str(port),
                                    "--wait-for-subscribers", "20"),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        wait_for(lambda: len(rx) >= 100, 30, "every message over ROS")
        time.sleep(0.5)
        assert proc.poll() is None, "with --foxglove-port the replay waits at the end"
    finally:
        proc.terminate()
        _, err = proc.communicate(timeout=30)
    assert [index(m) for _, m in rx] == list(range(100))
    assert f"Foxglove WebSocket server on ws://127.0.0.1:{port}" in err
    assert proc.returncode == 0 and "stopped after" in err, err  # SIGTERM: as ros2 bag play


# -- controls --------------------------------------------------------------------------------

SRV = "/ssi_bridge_replay/"


def indices(rx: list[tuple[float, JointState]]) -> list[int]:
    return [index(m) for _, m in rx]


def speed(part: list[tuple[float, JointState]]) -> float:
    """Bag seconds played per wall second over ``part`` (by the replay's publish times)."""
    bag = (index(part[-1][1]) - index(part[0][1])) * PERIOD_NS / 1e9
    return bag / (part[-1][0] - part[0][0])


def test_the_player_services(four_s: Path, probe: Probe) -> None:
    from ssi_bridge_msgs.srv import Seek, SetRate
    from std_srvs.srv import Trigger

    rx = probe.subscribe("/joint_states")
    proc = subprocess.Popen(command(four_s, "--quiet", "--start-paused",
                                    "--wait-for-subscribers", "20"),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        again = probe.call(Trigger, SRV + "pause", Trigger.Request())
        assert not again.success and "already paused" in again.message
        time.sleep(0.5)
        assert not rx, "started paused"

        for k in range(3):
            assert probe.call(Trigger, SRV + "play_next", Trigger.Request()).success
            wait_for(lambda: len(rx) > k, 10, f"message {k} after play_next")
        settle(rx, 0.3)
        assert indices(rx) == [0, 1, 2], "one message per play_next"

        bad = probe.call(SetRate, SRV + "set_rate", SetRate.Request(rate=0.0))
        assert not bad.success and "must be > 0" in bad.message
        assert probe.call(SetRate, SRV + "set_rate", SetRate.Request(rate=2.0)).success
        target = Seek.Request()
        target.time.sec, target.time.nanosec = divmod(T0 + 2_000_000_000, 10**9)
        seek = probe.call(Seek, SRV + "seek", target)
        assert seek.success and "2.000 s into the bag" in seek.message, seek.message
        assert probe.call(Trigger, SRV + "resume", Trigger.Request()).success
        wait_for(lambda: len(rx) >= 3 + 60, 20, "60 messages at 2x")
        assert index(rx[3][1]) == 200, "the first message after the seek is the one at 2 s"
        assert 1.3 < speed(rx[3:]) < 3.0, speed(rx[3:])

        assert probe.call(Trigger, SRV + "pause", Trigger.Request()).success
        settle(rx, 0.3)
        paused_at = len(rx)
        time.sleep(1.0)
        assert len(rx) == paused_at, "messages while paused"
        back = probe.call(Seek, SRV + "seek", Seek.Request(offset=3.5))
        assert back.success and "3.500 s into the bag" in back.message
        assert probe.call(Trigger, SRV + "resume", Trigger.Request()).success
        assert proc.wait(30) == 0, proc.communicate()[1]
    finally:
        if proc.poll() is None:
            proc.kill()
        out, err = proc.communicate(timeout=30)
    settle(rx)
    last = index(rx[paused_at - 1][1])
    assert indices(rx) == [0, 1, 2, *range(200, last + 1), *range(350, 400)], err
    assert f"replayed {len(rx)} messages" in out


class Screen:
    """What a program writes to a pseudo-terminal, read by a thread."""

    def __init__(self, master: int) -> None:
        self.master, self.text = master, ""
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self) -> None:
        while True:
            try:
                ready, _, _ = select.select([self.master], [], [], 0.1)
                if ready:
                    data = os.read(self.master, 4096)
                    if not data:
                        return
                    self.text += data.decode(errors="replace")
            except OSError:   # EIO: the program closed its end
                return

    def last_line(self) -> str:
        return re.split(r"[\r\n]", self.text.rstrip("\r\n"))[-1] if self.text else ""

    def shows(self, pattern: str) -> Callable[[], bool]:
        return lambda: re.search(pattern, self.last_line()) is not None


def _foreground(tty_fd: int) -> Callable[[], None]:
    """A preexec_fn: the child (leader of a new session) takes ``tty_fd`` as its controlling
    terminal and is its foreground process group, as a program started from a shell."""
    def preexec() -> None:
        fcntl.ioctl(tty_fd, termios.TIOCSCTTY, 0)
    return preexec


@contextmanager
def in_a_terminal(args: list[str]) -> Iterator[tuple[subprocess.Popen, Screen, int, int, list]]:
    """Run ``args`` on a new pseudo-terminal as its foreground program: (process, its screen,
    the master and slave ends, the terminal's settings from before the start). On exit the
    process is killed if still running and both ends are closed."""
    master, slave = os.openpty()
    settings = termios.tcgetattr(slave)
    proc = subprocess.Popen(args, stdin=slave, stdout=slave, stderr=slave, close_fds=True,
                            start_new_session=True, preexec_fn=_foreground(slave))
    try:
        yield proc, Screen(master), master, slave, settings
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
        os.close(slave)
        os.close(master)


def _the_keys_in_a_terminal_and_the_progress_line(four_s: Path, probe: Probe) -> None:
    rx = probe.subscribe("/joint_states")
    args = command(four_s, "--start-paused", "--wait-for-subscribers", "20")
    with in_a_terminal(args) as (proc, screen, master, slave, settings):
        wait_for(screen.shows(r"^\[P\] +0\.000 / 3\.990 s  t 1700000000\.000000000  "
                              r"rate 1\.00x  0 msgs"), 30, "the progress line, paused")
        time.sleep(0.3)
        assert not rx, "started paused"
        assert "keys: space pause/resume" in screen.text, "the keys are named"
        for k in range(2):
            os.write(master, b"\x1b[C")        # →
            wait_for(lambda: len(rx) > k, 10, f"message {k} after →")
        wait_for(screen.shows(r"^\[P\] +0\.010 / .* 2 msgs"), 10, "the line after two steps")
        os.write(master, b"\x1b[A")            # ↑
        wait_for(screen.shows(r"rate 1\.10x"), 10, "rate 1.10x after ↑")
        os.write(master, b"\x1b[B")            # ↓
        wait_for(screen.shows(r"rate 0\.99x"), 10, "rate 0.99x after ↓")
        os.write(master, b" ")                 # resume
        wait_for(screen.shows(r"^\[R\]"), 10, "running")
        wait_for(lambda: len(rx) >= 60, 20, "messages after space")
        assert 0.6 < speed(rx[2:]) < 1.5, speed(rx[2:])
        os.write(master, b" ")                 # pause
        wait_for(screen.shows(r"^\[P\]"), 10, "paused again")
        settle(rx, 0.3)
        paused_at = len(rx)
        time.sleep(1.0)
        assert len(rx) == paused_at, "messages while paused"
        os.write(master, b" ")
        assert proc.wait(60) == 0, screen.text[-2000:]
        assert termios.tcgetattr(slave) == settings, "the terminal gets its settings back"
    settle(rx)
    assert indices(rx) == list(range(400))
    assert "[E]" in screen.text and "replayed 400 messages" in screen.text, screen.text[-500:]


def _ctrl_c_in_the_terminal_ends_the_replay_and_gives_the_terminal_back(four_s: Path) -> None:
    args = command(four_s, "--wait-for-subscribers", "0")
    with in_a_terminal(args) as (proc, screen, master, slave, settings):
        wait_for(screen.shows(r"^\[R\]"), 30, "the progress line, running")
        os.write(master, b"\x03")              # Ctrl-C: the terminal sends SIGINT
        assert proc.wait(30) == 0, screen.text[-2000:]  # as ros2 bag play (ros2bag >= 0.18)
        assert termios.tcgetattr(slave) == settings, "the terminal gets its settings back"
    assert "Traceback" not in screen.text, screen.text[-2000:]


def _sigint_stops_the_replay_with_exit_0_like_ros2_bag_play(four_s: Path,
                                                            probe: Probe) -> None:
    """kill -INT (what ``ros2 run`` and ``ros2 launch`` forward): exit 0, no traceback, and
    what was published before reaches the subscriber. The child gets SIGINT's default back
    (test/conftest.py's preexec_fn): a background job starts with it ignored."""
    rx = probe.subscribe("/joint_states")
    proc = subprocess.Popen(command(four_s, "--quiet", "--wait-for-subscribers", "20"),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        wait_for(lambda: len(rx) >= 50, 30, "50 messages played")
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
    assert proc.returncode == 0 and "stopped after" in err, err
    assert "Traceback" not in err, err
    settle(rx)
    assert 50 <= len(rx) < 400 and indices(rx) == list(range(len(rx))), indices(rx)[-5:]


def _loop_plays_the_selection_again_from_the_start_offset(one_s: Path, probe: Probe) -> None:
    rx = probe.subscribe("/joint_states")
    proc = subprocess.Popen(command(one_s, "--quiet", "--loop", "--start-offset", "0.5",
                                    "--playback-duration", "0.2", "--wait-for-subscribers", "20"),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        wait_for(lambda: len(rx) >= 63, 30, "three passes")
    finally:
        proc.terminate()
        _, err = proc.communicate(timeout=30)
    assert indices(rx)[:63] == [*range(50, 71)] * 3, err
    assert proc.returncode == 0 and "stopped after" in err, err


def _disabled_keys_leave_the_input_alone(four_s: Path, probe: Probe) -> None:
    rx = probe.subscribe("/joint_states")
    args = command(four_s, "--start-paused", "--disable-keyboard-controls",
                   "--wait-for-subscribers", "20")
    with in_a_terminal(args) as (_, screen, master, slave, _):
        wait_for(screen.shows(r"^\[P\]"), 30, "the progress line, paused")
        os.write(master, b" \x1b[C")
        time.sleep(1.5)
        assert not rx and screen.shows(r"^\[P\] .* 0 msgs")(), screen.last_line()
        assert "keys:" not in screen.text
        assert termios.tcgetattr(slave)[3] & termios.ICANON, "the terminal stays line-buffered"


# -- the test functions of the parts above that run one after the other on one probe ----------
# (each part was a test function of its own; merged so that one DDS domain and probe serve
# both, every assertion kept: docs/testing.md)

def test_a_replay_that_waits_at_the_end_or_loops_stops_on_sigterm_with_exit_0(
        one_s: Path, probe: Probe) -> None:
    """--foxglove-port keeps the replay waiting at the end, --loop plays the selection again
    from the start offset; SIGTERM ends either with exit 0, as ``ros2 bag play``."""
    _foxglove_view_and_ros_publishing_together(one_s, probe)
    _loop_plays_the_selection_again_from_the_start_offset(one_s, probe)


def test_sigint_or_ctrl_c_in_a_terminal_stops_the_replay_with_exit_0(four_s: Path,
                                                                     probe: Probe) -> None:
    """kill -INT and the terminal's Ctrl-C: exit 0 and no traceback, as ``ros2 bag play``."""
    _sigint_stops_the_replay_with_exit_0_like_ros2_bag_play(four_s, probe)
    _ctrl_c_in_the_terminal_ends_the_replay_and_gives_the_terminal_back(four_s)


def test_the_keys_in_a_terminal_and_the_progress_line_or_none_when_disabled(
        four_s: Path, probe: Probe) -> None:
    """The keys (space, →, ↑, ↓) and the progress line; --disable-keyboard-controls leaves the
    input alone and the terminal line-buffered."""
    _the_keys_in_a_terminal_and_the_progress_line(four_s, probe)
    _disabled_keys_leave_the_input_alone(four_s, probe)
