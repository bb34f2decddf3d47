"""``ros2 run ssi_bridge ssi_bridge_managed_node``: the bridge waiting for its lifecycle manager.

The same node as ``ssi_bridge_node`` (one lifecycle node class, ``ros/node.py``) with its
``autostart`` parameter off by default: it starts unconfigured and follows ``~/change_state``
(configure, activate, deactivate, cleanup, shutdown), see docs/node.md "Lifecycle".
Same command line, parameters and stop handling as ``ssi_bridge_node``.
"""

from __future__ import annotations

import sys

from ssi_bridge.tools.ssi_bridge_node import main as _main


def main(args: list[str] | None = None) -> int:
    """Run the node with autostart off by default until interrupted (exit codes as
    ssi_bridge_node)."""
    return _main(args, managed=True)


if __name__ == "__main__":
    sys.exit(main())
