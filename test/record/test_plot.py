"""plot: session PNG of the expected size with each joint's curve in its own axes; --frame."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pytest

from ssi_bridge.record.frame_diagram import frame_levels
from ssi_bridge.record.plot import plot_session

from .conftest import JOINTS


def colour_pixels(img: np.ndarray, bbox, rgb: tuple[float, float, float]) -> int:  # type: ignore[no-untyped-def]
    """Pixels close to ``rgb`` inside a display-space bbox (origin bottom-left)."""
    h = img.shape[0]
    x0, x1 = int(bbox.x0), int(bbox.x1)
    y0, y1 = h - int(bbox.y1), h - int(bbox.y0)
    region = img[y0:y1, x0:x1, :3]
    return int((np.abs(region - np.array(rgb)).max(axis=2) < 0.15).sum())


def test_session_png_has_content_per_joint(session_bag: Path, tmp_path: Path) -> None:
    out = tmp_path / "session.png"
    fig, axes = plot_session(session_bag, out, dpi=80)
    img = mpimg.imread(out)
    width, height = fig.get_size_inches() * 80
    assert img.shape[:2] == (round(height), round(width))
    renderer = fig.canvas.get_renderer()
    for k, joint in enumerate(JOINTS):
        colour = mpimg_colour(f"C{k}")
        for kind in ("pos", "vel"):
            bbox = axes[f"{kind}:{joint}"].get_window_extent(renderer)
            assert colour_pixels(img, bbox, colour) > 200, f"no {kind} curve for {joint}"
        other = mpimg_colour(f"C{1 - k}")
        bbox = axes[f"pos:{joint}"].get_window_extent(renderer)
        assert colour_pixels(img, bbox, other) == 0, f"{joint} axes show the other joint"
    diag = axes["diagnostics"].get_window_extent(renderer)
    assert colour_pixels(img, diag, mpimg_colour("tab:red")) > 50   # ERROR levels drawn
    assert colour_pixels(img, axes["events"].get_window_extent(renderer),
                         mpimg_colour("tab:purple")) > 20


def mpimg_colour(name: str) -> tuple[float, float, float]:
    from matplotlib.colors import to_rgb
    return to_rgb(name)


def test_frame_levels_follow_ssi_timing() -> None:
    lv = frame_levels(0b101, 3, 1e6, 5e-6)
    # clock: idle high, 4 falling edges (n + 1 clocks) at 0, 1, 2, 3 us
    falls = lv.clock_t[1:-1][lv.clock[1:-1] == 0]
    assert np.allclose(falls, [0, 1e-6, 2e-6, 3e-6])
    # the master samples on each rising edge, then the encoder shifts: pause 1, MSB..LSB = 1 0 1
    def level(t: float) -> int:
        return int(lv.data[np.searchsorted(lv.data_t, t, side="right") - 1])
    assert [level(t - 1e-9) for t in lv.samples] == [1, 1, 0, 1]   # sampled before the shift
    # monoflop: low after the LSB until tm after the last falling edge, then idle high
    assert level(3.6e-6) == 0 and level(3e-6 + 5e-6 + 1e-9) == 1


def test_cli_frame_and_errors(tmp_path: Path) -> None:
    out = tmp_path / "frame.png"
    ok = subprocess.run([sys.executable, "-m", "ssi_bridge.tools.plot", "--frame",
                         "--value", "0x1ABCDE5", "--bits", "25", "--error-bits", "2",
                         "-o", str(out)], capture_output=True, text=True, timeout=60, check=False)
    assert ok.returncode == 0, ok.stderr
    assert mpimg.imread(out).shape[1] > 800
    bad = subprocess.run([sys.executable, "-m", "ssi_bridge.tools.plot",
                          str(tmp_path / "nope"), "-o", str(out)], capture_output=True,
                         text=True, timeout=60, check=False)
    assert bad.returncode == 2 and "no such bag" in bad.stderr


@pytest.mark.parametrize("n_bits", [1, 13, 32])
def test_frame_levels_sizes(n_bits: int) -> None:
    lv = frame_levels((1 << n_bits) - 1, n_bits, 250e3, 20e-6)
    assert len(lv.samples) == n_bits + 1


def test_ctrl_c_cuts_a_plot_short_in_one_line_with_130(session_bag: Path, tmp_path: Path) -> None:
    """A batch tool stopped before it is done exits non-zero (the shell's 128 + SIGINT), with
    one line instead of a KeyboardInterrupt traceback. SIGINT goes in once matplotlib's
    library is mapped: plot imports it inside main, then reads, draws and writes (seconds)."""
    out = tmp_path / "cut.png"
    proc = subprocess.Popen([sys.executable, "-m", "ssi_bridge.tools.plot", str(session_bag),
                             "-o", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    maps = Path(f"/proc/{proc.pid}/maps")
    deadline = time.monotonic() + 60
    while "matplotlib" not in maps.read_text():
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.002)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "plot: interrupted" in err and "Traceback" not in err, err
