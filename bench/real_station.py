"""The node as a real deployment runs it, for the driver-only figures of node_driver.py.

With ``simulation.enabled: true`` the node's own bus end is the simulated wire
(``sim/gateway/wire_bus.py``): the node's SYNC is paced at bit time in the node's process and
the simulator's modules are loaded there. A real deployment has neither: its node runs with
``simulation.enabled:=false`` on an interface that a separate device answers. Here that device
is the ``station`` program, started as a process of its own on a ``udp_multicast`` group, and
the node is started on the same group with the simulation off, so the node process holds the
driver alone.
"""

from __future__ import annotations

import contextlib
import select
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from ssi_bridge.base.udp_bus import derive_channel
# test/ is on the path: node_procs.py, which every importer of this module loads, puts it there
from support.stations import stop_station  # type: ignore[import-not-found]

STATION_EXE_PARTS = ("install", "ssi_bridge", "lib", "ssi_bridge", "station")
#: the ``station`` program's line once it has sent its boot-up (sim/program.py READY)
READY = b"station ready"
READY_TIMEOUT_S = 20.0


def real_params(tag: str) -> dict[str, Any]:
    """The node parameters of a real deployment on the group of ``tag``: no simulation,
    udp_multicast on loopback."""
    return {"simulation.enabled": False, "bus.interface": "udp_multicast",
            "bus.channel": derive_channel(f"bench_real_{tag}")}


@contextlib.contextmanager
def station_process(repo: Path, params_file: Path, channel: str, env: dict[str, str],
                    log: Path, args: tuple[str, ...] = ()) -> Iterator[subprocess.Popen[bytes]]:
    """The installed ``station`` on ``params_file``'s joints and ``channel``, ready (its
    boot-up sent) while the block runs, stopped by its PID (SIGINT, then SIGKILL) after.
    ``args``: further options of the station program (e.g. ``--priority``).

    :raises RuntimeError: the station exited or did not say it is ready within
        :data:`READY_TIMEOUT_S`
    """
    exe = repo.joinpath(*STATION_EXE_PARTS)
    with open(log, "wb") as err:
        proc = subprocess.Popen([str(exe), "--params-file", str(params_file),
                                 "--interface", "udp_multicast", "--channel", channel,
                                 *args],
                                stdout=subprocess.PIPE, stderr=err, env=env,
                                start_new_session=True)
    stdout = proc.stdout
    assert stdout is not None  # stdout=PIPE
    try:
        deadline = time.monotonic() + READY_TIMEOUT_S
        line = b""
        while not line.startswith(READY):
            left = deadline - time.monotonic()
            if left <= 0 or proc.poll() is not None:
                raise RuntimeError(f"station not ready (exit {proc.poll()}): "
                                   f"{log.read_text(errors='replace')[-1500:]}")
            if select.select([stdout], [], [], left)[0]:
                line = stdout.readline()
        yield proc
    finally:
        stop_station(proc)
        stdout.close()


__all__ = ["real_params", "station_process"]
