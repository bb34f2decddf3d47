"""No private part of python-can, canopen or rclpy is touched outside its adapter module.

Each library has one adapter, the only module that may touch what the library does not
offer publicly, each use with a canary test that fails by name on a release that changed it:
``base/can_compat.py`` (test/base/test_can_compat_multicast.py,
test/base/test_library_compat.py), ``base/canopen_compat.py``
(test/base/test_canopen_network.py, test/base/test_library_compat.py) and
``ros/rclpy_compat.py`` (test/ros/test_rclpy_compat.py).

The rule, checked on the syntax tree of every module of ``ssi_bridge/`` (the scanner:
test/support/private_access.py; what is private is read from the installed libraries'
own sources by test/support/library_private.py, not listed). Outside the adapters a module must not:

1. read, write or delete ``x._name`` (or ``getattr``/``setattr``/``hasattr``/``delattr``
   with ``"_name"``) where ``_name`` is a private name of the libraries, unless ``x`` is a
   module-local object: ``self``/``cls`` of a class that derives from no library class, or
   any object when the module itself defines ``_name`` (its own classes' attribute, or a
   top-level name). In a class derived from a library class, ``self._name``/``super()._name``
   is the library's when the library classes in its MRO define or use ``_name``;
2. override a library class's private method, unless the library's docstring of it invites
   overriding (``BusABC._recv_internal``, ``_send_periodic_internal``): such an override
   may call the default through ``super()``;
3. set a library class's UPPER_CASE class attribute (``RESPONSE_TIMEOUT``,
   ``NOTIFIER_CYCLE``): on an instance, on the class, or by overriding it in a subclass;
4. change a library object's registry in place (``network.listeners[:] = ...``,
   ``.append``, ``del network.nodes[...]``) or replace it by a new container: a registry is
   an attribute the library's own methods change in place (``listeners``, ``subscribers``,
   ``nodes``, ``data_store``, ...), unless the receiver is a module-local object as in 1;
5. import or reach a private library module or name (``rclpy._rclpy_pybind11``,
   ``rclpy.impl``);
6. (a module that imports rclpy) touch an rclpy object's ``handle`` (its pybind11
   implementation object).

Sound where it matters and simple: a private name is the libraries' by name alone unless
the module owns it, so a module cannot reach into a library object by choosing an
unknown receiver. What it does not see: an access built at run time (``getattr`` with a
computed name), a library private of the same name as one the module defines itself, and
the reading of a library's public-named attributes (``network.subscribers.get``: no rule
tells a library's undocumented attribute from its documented ones by the name alone).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from support.private_access import ADAPTERS, LIBRARIES, library_facts, scan

REPO = Path(__file__).resolve().parents[2]


def _package() -> dict[str, str]:
    return {str(p.relative_to(REPO)): p.read_text(encoding="utf-8")
            for p in sorted((REPO / "ssi_bridge").rglob("*.py"))}


def test_no_module_touches_a_library_private_outside_the_adapters() -> None:
    found = scan(_package())
    assert not found, "library internals outside the adapters (move them into " \
        "base/can_compat.py, base/canopen_compat.py or ros/rclpy_compat.py, with a canary):\n" \
        + "\n".join(found)


def test_one_adapter_per_library_and_each_uses_its_library() -> None:
    package = _package()
    for adapter, library in zip(ADAPTERS, LIBRARIES, strict=True):
        assert f"import {library}" in package[adapter] or f"from {library}" in package[adapter]


def test_the_libraries_private_parts_are_read_from_their_sources() -> None:
    """The scanner's facts come from the installed libraries: what this package's adapters
    rely on is among them (else the scan above could pass by seeing nothing)."""
    facts = library_facts()
    assert {"_recv_internal", "_is_shutdown", "_matches_filters", "_multicast", "_socket",
            "_parameter_overrides", "_futures"} <= facts.private
    assert {"_recv_internal", "_send_periodic_internal"} <= facts.hooks
    assert "_is_shutdown" not in facts.hooks
    assert {"RESPONSE_TIMEOUT", "MAX_RETRIES", "PAUSE_BEFORE_SEND", "NOTIFIER_CYCLE"} \
        <= facts.config
    assert {"subscribers", "nodes", "listeners", "data_store"} <= facts.tables


#: planted violations: (what, source); each must be reported outside an adapter
PLANTED = [
    ("private attribute of a bus", "import can\n\ndef f(bus: can.BusABC):\n"
                                   "    return bus._recv_internal(0.1)\n"),
    ("getattr with a private name", "def f(node):\n"
                                    "    return getattr(node, '_parameter_overrides', {})\n"),
    ("setattr with a private name", "def f(bus):\n    setattr(bus, '_is_shutdown', True)\n"),
    ("private state of the base class", "import can\n\nclass B(can.BusABC):\n"
                                        "    def gone(self):\n"
                                        "        return self._is_shutdown\n"),
    ("private state of a re-exported base class",
     "from ssi_bridge.base.can_compat import UdpMulticastBus\n\n"
     "class B(UdpMulticastBus):\n    def __init__(self, s):\n        self._multicast = s\n"),
    ("private method overridden", "import can\n\nclass B(can.BusABC):\n"
                                  "    @staticmethod\n"
                                  "    def _detect_available_configs():\n"
                                  "        return []\n"),
    ("private default called outside its override",
     "import can\n\nclass B(can.BusABC):\n    def recv_once(self):\n"
     "        return super()._recv_internal(0.0)\n"),
    ("listener table replaced in place", "def f(network, listener):\n"
                                         "    network.listeners[:] = [listener]\n"),
    ("listener table appended to", "def f(network, listener):\n"
                                   "    network.listeners.append(listener)\n"),
    ("listener table replaced", "def f(network, listener):\n"
                                "    network.listeners = [listener]\n"),
    ("node table changed", "def f(network):\n    network.nodes.pop(5, None)\n"),
    ("own registry of a library subclass", "import canopen\n\n"
                                           "class N(canopen.Network):\n"
                                           "    def only(self, listener):\n"
                                           "        self.listeners[:] = [listener]\n"),
    ("data store cleared", "def f(node):\n    node.data_store.clear()\n"),
    ("SDO timing set on an instance", "def f(node):\n    node.sdo.RESPONSE_TIMEOUT = 1.0\n"),
    ("SDO retries set on the class", "import canopen\n\n"
                                     "canopen.sdo.SdoClient.MAX_RETRIES = 3\n"),
    ("notifier cycle set", "def f(network):\n    network.NOTIFIER_CYCLE = 0.05\n"),
    ("class setting overridden", "from canopen.sdo.client import SdoClient\n\n"
                                 "class S(SdoClient):\n    PAUSE_BEFORE_SEND = 0.0\n"),
    ("private module imported", "from rclpy._rclpy_pybind11 import RCLError\n"),
    ("implementation package imported",
     "from rclpy.impl.implementation_singleton import rclpy_implementation\n"),
    ("private name imported", "from can.bus import _SelfRemovingCyclicTask\n"),
    ("implementation package reached", "import rclpy\n\n"
                                       "LOGGER = rclpy.impl.rcutils_logger.RcutilsLogger\n"),
    ("rclpy handle used", "import rclpy\n\ndef take(service, kind):\n"
                          "    with service.handle:\n"
                          "        return service.handle.service_take_request(kind)\n"),
]

#: legitimate code the rule must let pass
ALLOWED = [
    ("own private of another object of the module", "class A:\n"
                                                    "    def __init__(self):\n"
                                                    "        self._pos = 0\n\n"
                                                    "def pos(a):\n    return a._pos\n"),
    ("own private in a library subclass", "import can\n\nclass B(can.BusABC):\n"
                                          "    def __init__(self, inner):\n"
                                          "        self._inner = inner\n"),
    ("documented hook overridden, default called",
     "import can\n\nclass B(can.BusABC):\n    def _recv_internal(self, timeout):\n"
     "        return super()._recv_internal(timeout)\n"),
    ("public field of a frame set", "def f(msg):\n    msg.channel = None\n"
                                    "    msg.data = bytearray()\n"),
    ("own registry", "class R:\n    def __init__(self):\n        self.listeners = []\n\n"
                     "def f(r, x):\n    r.listeners.append(x)\n"),
    ("public API", "import canopen\n\ndef f(network, cb):\n"
                   "    network.subscribe(0x185, cb)\n    del network[5]\n"),
]


@pytest.mark.parametrize(("what", "source"), PLANTED, ids=[w for w, _ in PLANTED])
def test_a_planted_violation_is_found(what: str, source: str) -> None:
    found = scan({"ssi_bridge/client/planted.py": source})
    assert found and all(f.startswith("ssi_bridge/client/planted.py:") for f in found), what
    assert scan({ADAPTERS[0]: source}) == [], "the adapters may"


@pytest.mark.parametrize(("what", "source"), ALLOWED, ids=[w for w, _ in ALLOWED])
def test_legitimate_code_passes(what: str, source: str) -> None:
    assert scan({"ssi_bridge/client/fine.py": source}) == [], what


def test_a_planted_violation_in_the_package_fails_the_scan() -> None:
    """The package scan itself fails on one planted line (here: ros/params.py's old read)."""
    package = _package()
    package["ssi_bridge/ros/params.py"] += (
        "\n\ndef _given(node):\n    return getattr(node, '_parameter_overrides', {})\n")
    found = scan(package)
    assert len(found) == 1 and found[0].startswith("ssi_bridge/ros/params.py:"), found
