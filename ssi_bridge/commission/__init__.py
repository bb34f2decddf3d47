"""Commissioning: read a station off the bus and write the params file the node starts with.

``discover`` (gateways, identity, slots) -> ``sample`` (raw frames over SDO and the read
handshake) -> ``infer`` (moving bits, code, direction) -> ``rank`` (families of the manuals)
-> ``analyze`` (one slot's verdict) -> ``params_out`` / ``report``; ``run.commission`` does it
all, ``listen_only`` watches a bus another master drives. Part of the driver: it imports the
protocol and the client, never the simulator. Rules and manual sections:
docs/commissioning.md.
"""
