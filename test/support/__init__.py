"""Helpers shared by several test folders and the benchmarks (never imported by the driver,
never a test module): ``truth``, the truth oracle of the simulated station; ``ros_process``,
``stations``, ``lifecycle`` and ``liveview``, the node and station processes of the node
tests and the clients that talk to them; ``virtual_bus``, a test's private virtual channel and
a scripted SSI line; ``waiting``, polling until a condition holds."""
