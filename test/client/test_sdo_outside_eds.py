"""``~/sdo_read`` of an object the EDS does not know: what the code does is what the page says.

core/sdo_access.ObjectAccess uploads first and decodes by type after: a station without the
object answers its abort (CiA 301 0x06020000 "object does not exist") and no ``data_type`` is
needed to learn that; a station that has an object the master's EDS lacks (a real gateway's
object the EDS file leaves out; here 0x1018 Identity taken out of the master's dictionary)
answers bytes the read cannot decode without a ``data_type``, and says so with their length
and hex; named, they decode. docs/node.md used to say such a read "needs a data_type", as if
it were refused before asking. A real gateway model and master on python-can's virtual bus.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from ssi_bridge.core.bridge import Bridge
from ssi_bridge.core.joint import Joint
from ssi_bridge.core.sdo_access import ObjectAccess
from ssi_bridge.exceptions import ConfigError, SdoAbortError
from ssi_bridge.protocol.settings import JointSettings

DOC = Path(__file__).resolve().parents[2] / "docs" / "node.md"
IDENTITY = 0x1018
#: what the page quotes of the refusal
REFUSAL = "is not in the EDS, so its type is unknown: name a data_type (read 4 byte(s):"


@pytest.fixture
def access(station):
    _gateway, client, _readers = station
    joint = Joint(JointSettings(name="j", slot=1), velocity_window=3, max_speed=0.0,
                  stale_cycles=5)
    return ObjectAccess(Bridge({"j": joint}, lambda _name: client)), client


def test_a_read_outside_the_eds_asks_the_station_and_names_what_it_got(access):
    objects, client = access
    vendor = int(client.read_object(IDENTITY, 1))
    del client.node.object_dictionary[IDENTITY]  # the master's EDS lacks what the station has
    # no such object at the station either: its abort, no data_type needed
    with pytest.raises(SdoAbortError) as abort:
        objects.read(0, "", 0x1234, 0, "")
    assert abort.value.code == 0x0602_0000
    # the station has it: the bytes come back, the type is asked for
    with pytest.raises(ConfigError, match=r"read 4 byte\(s\): ") as refused:
        objects.read(0, "", IDENTITY, 1, "")
    assert REFUSAL in str(refused.value), refused.value
    assert vendor.to_bytes(4, "little").hex() in str(refused.value)
    dtype, value, _text = objects.read(0, "", IDENTITY, 1, "UNSIGNED32")
    assert (dtype.name, value) == ("UNSIGNED32", vendor)


def test_the_page_says_what_the_read_does():
    text = " ".join(DOC.read_text(encoding="utf-8").split())
    assert REFUSAL in text, "docs/node.md does not quote the refusal of ~/sdo_read"
    assert "needs a `data_type`; a read whose size" not in text
