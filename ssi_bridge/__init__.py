"""ssi_bridge: a simulated Eaton XN-1SSI SSI module behind a CANopen gateway, bridged to ROS 2.

The stages of the data path (ARCHITECTURE.md) are sub-packages, each importing only from
stages to its left: encoder -> line -> module -> gateway -> client -> ros -> record.
"""

__version__ = "0.1.0"
