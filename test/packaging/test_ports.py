"""The objects the node hands to core fit core's Protocols (``core/ports.py``), by mypy.

core imports neither the master nor the simulator, so nothing in the checked folders assigns
a ``BridgeClient`` to a ``StationClient``: the node does (``ros/``, not checked yet). This
test states those assignments in a snippet and has mypy check it with the project's config,
so a port and the class it stands for cannot drift apart.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]

SNIPPET = '''
from canopen.objectdictionary import ODVariable

from ssi_bridge.client.listener import ListenOnlyClient
from ssi_bridge.client.master import BridgeClient
from ssi_bridge.client.sdo import SdoAccess
from ssi_bridge.core.ports import DictionaryEntry, FaultPort, RawSdo, StationClient
from ssi_bridge.sim.supervisor.faults import FaultInjector, StationFaults


def fits(master: BridgeClient, listener: ListenOnlyClient, sdo: SdoAccess, entry: ODVariable,
         one: FaultInjector, several: StationFaults) -> None:
    clients: list[StationClient] = [master, listener]
    raw: RawSdo = sdo
    variable: DictionaryEntry = entry
    faults: list[FaultPort] = [one, several]
'''


def test_the_node_s_objects_fit_core_s_ports(tmp_path: Path) -> None:
    snippet = tmp_path / "ports_fit.py"
    snippet.write_text(SNIPPET, encoding="utf-8")
    env = {**os.environ, "MYPYPATH": str(REPO)}
    out = subprocess.run([sys.executable, "-m", "mypy", "--config-file", "setup.cfg",
                          "--follow-imports=silent", "--no-incremental", str(snippet)],
                         capture_output=True, text=True, cwd=REPO, env=env, timeout=300)
    assert out.returncode == 0, out.stdout[-4000:] + out.stderr[-2000:]
