"""One picture of a recorded session: what every joint did and what happened to the bridge.

Rows, sharing the time axis (seconds from the start of the bag): position and velocity of
each joint (from ``joint_states``), the diagnostics level of every DiagnosticStatus name as a
coloured band (OK green, WARN orange, ERROR red, STALE grey), and the events (presets,
register writes, faults...) as annotated markers (purple; red when the request failed).
"""

from __future__ import annotations

import logging
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402

from ssi_bridge.exceptions import RecordingError  # noqa: E402
from ssi_bridge.record.reader import Bag  # noqa: E402

logger = logging.getLogger(__name__)

LEVEL_COLOURS = {0: "tab:green", 1: "tab:orange", 2: "tab:red", 3: "tab:gray"}
LEVEL_NAMES = {0: "OK", 1: "WARN", 2: "ERROR", 3: "STALE"}


@dataclass
class SessionData:
    """The series a session plot needs, times in seconds from the bag start."""

    start_ns: int = 0
    #: joint -> (t, position, velocity)
    joints: dict[str, tuple[list[float], list[float], list[float]]] = field(
        default_factory=lambda: defaultdict(lambda: ([], [], [])))
    #: status name -> [(t, level)]
    diagnostics: dict[str, list[tuple[float, int]]] = field(
        default_factory=lambda: defaultdict(list))
    #: (t, kind, joint, success, message)
    events: list[tuple[float, str, str, bool, str]] = field(default_factory=list)
    end_s: float = 0.0


def _topic_of(bag: Bag, type_name: str) -> list[str]:
    """Recorded topics of a type."""
    return [t.name for t in bag.topics.values() if t.type == type_name]


def load_session(path: Path) -> SessionData:
    """Read joint states, diagnostics and events of a bag (ours or rosbag2's).

    :raises RecordingError: the bag cannot be read or has no JointState topic

    :param path: the bag directory or MCAP file
    """
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import JointState

    from ssi_bridge_msgs.msg import Event

    with Bag(path) as bag:
        data = SessionData(start_ns=bag.start_ns, end_s=(bag.end_ns - bag.start_ns) / 1e9)
        js = _topic_of(bag, "sensor_msgs/msg/JointState")
        diag = _topic_of(bag, "diagnostic_msgs/msg/DiagnosticArray")
        ev = _topic_of(bag, "ssi_bridge_msgs/msg/Event")
        if not js:
            raise RecordingError(f"{bag.path}: no sensor_msgs/msg/JointState topic to plot")
        for topic, stamp, msg in bag.decoded(js + diag + ev):
            t = (stamp - bag.start_ns) / 1e9
            if isinstance(msg, JointState):
                for k, name in enumerate(msg.name):
                    series = data.joints[name]
                    series[0].append(t)
                    series[1].append(msg.position[k] if k < len(msg.position) else float("nan"))
                    series[2].append(msg.velocity[k] if k < len(msg.velocity) else float("nan"))
            elif isinstance(msg, DiagnosticArray):
                for st in msg.status:
                    level = st.level if isinstance(st.level, int) else st.level[0]
                    data.diagnostics[st.name].append((t, int(level)))
            elif isinstance(msg, Event):
                data.events.append((t, msg.kind, msg.joint, bool(msg.success), msg.message))
    return data


def draw_session(data: SessionData, title: str = "", width_in: float = 12.0,
                 dpi: int = 100) -> tuple[Figure, dict[str, object]]:
    """Draw the session figure; return it and the axes by role (``pos:<joint>`` ...).

    :param data: what :func:`load_session` read
    :param title: the figure's title
    :param width_in: the figure's width (inches)
    :param dpi: its resolution
    """
    joints = sorted(data.joints)
    rows = 2 * len(joints) + (1 if data.diagnostics else 0) + (1 if data.events else 0)
    ratios = [3.0] * (2 * len(joints)) + [1.0] * (rows - 2 * len(joints))
    fig, axes = plt.subplots(rows, 1, sharex=True, figsize=(width_in, 1.6 * sum(ratios) / 2 + 1),
                             dpi=dpi, gridspec_kw={"height_ratios": ratios}, squeeze=False)
    named: dict[str, object] = {}
    row = 0
    for k, joint in enumerate(joints):
        t, pos, vel = data.joints[joint]
        colour = f"C{k % 10}"
        for kind, values, unit in (("pos", pos, "position\n[rad | m]"),
                                   ("vel", vel, "velocity\n[rad/s | m/s]")):
            ax = axes[row][0]
            ax.plot(t, values, color=colour, lw=1.5)
            ax.set_ylabel(f"{joint}\n{unit}", fontsize=8)
            ax.grid(alpha=0.3)
            named[f"{kind}:{joint}"] = ax
            row += 1
    if data.diagnostics:
        ax = axes[row][0]
        names = sorted(data.diagnostics)
        for y, name in enumerate(names):
            points = data.diagnostics[name]
            for i, (t0, level) in enumerate(points):
                t1 = points[i + 1][0] if i + 1 < len(points) else data.end_s
                ax.broken_barh([(t0, max(t1 - t0, 1e-6))], (y - 0.4, 0.8),
                               color=LEVEL_COLOURS.get(level, "black"), lw=0)
        ax.set_yticks(range(len(names)), [n.split(": ", 1)[-1] for n in names],
                      fontsize=7)
        ax.set_ylim(-0.6, len(names) - 0.4)
        ax.set_ylabel("diagnostics", fontsize=8)
        handles = [Rectangle((0, 0), 1, 1, color=c) for c in LEVEL_COLOURS.values()]
        ax.legend(handles, LEVEL_NAMES.values(), fontsize=7, ncol=4, loc="upper right")
        named["diagnostics"] = ax
        row += 1
    if data.events:
        ax = axes[row][0]
        for i, (when, kind, joint, ok, message) in enumerate(data.events):
            colour = "tab:purple" if ok else "tab:red"
            ax.plot([when], [0], marker="v", color=colour, ms=8)
            for other in axes[:row]:
                other[0].axvline(when, color=colour, lw=0.6, alpha=0.5)
            ax.annotate(f"{kind}{'' if ok else ' FAILED'}\n{joint}", (when, 0),
                        (0, 8 + 12 * (i % 2)), textcoords="offset points", fontsize=7,
                        ha="center", color=colour)
        ax.set_yticks([])
        ax.set_ylim(-0.5, 2.0)
        ax.set_ylabel("events", fontsize=8)
        named["events"] = ax
    axes[-1][0].set_xlabel("time since start of recording [s]")
    fig.suptitle(title or "ssi_bridge session", fontsize=11)
    fig.tight_layout()
    return fig, named


def plot_session(bag: Path, output: Path, dpi: int = 100) -> tuple[Figure, dict[str, object]]:
    """Load ``bag`` and save its session figure as PNG at ``output``.

    :param dpi: the PNG's resolution
    :returns: the figure and its axes by role (:func:`draw_session`)
    :raises RecordingError: the bag cannot be read or has no JointState topic
    """
    data = load_session(bag)
    fig, named = draw_session(data, title=f"ssi_bridge session {Path(bag).name}", dpi=dpi)
    fig.savefig(output, dpi=dpi)
    return fig, named
