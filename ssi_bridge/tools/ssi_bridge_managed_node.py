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
    """Entry point of ``ssi_bridge_managed_node``: the node with ``autostart`` off by default,
    until interrupted.

    :param args: the command line without the program name (default: ``sys.argv[1:]``)
    :returns: the exit code, as :func:`ssi_bridge.tools.ssi_bridge_node.main`
    """
    return _main(args, managed=True)


if __name__ == "__main__":
    sys.exit(main())
