"""The XN-1SSI SSI technology module model (000 chapters 1 and 2); pure Python, no bus code.

Public API: :class:`Xn1Ssi` (``xn1ssi.py``), the register table (``registers.py``), the
process images (``images.py``), diagnostics and EMCY edges (``diagnostics.py``) and the
retentive storage (``store.py``).  See docs/module.md.
"""

from ssi_bridge.sim.module.bank import ENDURANCE_LIMIT, ENDURANCE_WARNING, Endurance
from ssi_bridge.protocol.diagnostics import Diag, DiagEdge, DiagTracker, cam_state, diag_edges
from ssi_bridge.protocol.images import (
    CmpControl, CmpStatus, Control, ModuleStatus, ProcessInput, ProcessOutput, ReadStatus,
    WriteRequest, WriteStatus,
)
from ssi_bridge.protocol.registers import BIT_RATES_HZ, Para1, Reg, describe_refusal, validate_para1
from ssi_bridge.sim.module.store import BankSnapshot, MemoryStore, RetentiveStore
from ssi_bridge.sim.module.xn1ssi import Xn1Ssi

__all__ = [
    "BIT_RATES_HZ", "BankSnapshot", "CmpControl", "CmpStatus", "Control", "Diag", "DiagEdge",
    "DiagTracker", "ENDURANCE_LIMIT", "ENDURANCE_WARNING", "Endurance", "MemoryStore",
    "ModuleStatus", "Para1", "ProcessInput", "ProcessOutput", "ReadStatus", "Reg",
    "RetentiveStore", "WriteRequest", "WriteStatus", "Xn1Ssi", "cam_state", "describe_refusal",
    "diag_edges", "validate_para1",
]
