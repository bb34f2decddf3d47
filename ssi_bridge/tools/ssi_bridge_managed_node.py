"""``ros2 run ssi_bridge ssi_bridge_managed_node``: the bridge as a lifecycle (managed) node.

Same command line, parameters and stop handling as ``ssi_bridge_node``; it starts
unconfigured and follows ``~/change_state`` (configure, activate, deactivate, cleanup,
shutdown), see docs/node.md "Managed node".
"""

from __future__ import annotations

import sys

from ssi_bridge.tools.ssi_bridge_node import main as _main


def main(args: list[str] | None = None) -> int:
    """Run the managed node until interrupted (exit codes as ssi_bridge_node)."""
    return _main(args, managed=True)


if __name__ == "__main__":
    sys.exit(main())
