"""The clear pulse of the comparator flags: CLR_CMPx for one module cycle, then released.

000 comparator table: CLR_CMPx resets FLAG_CMPx unless the values match ("Reset of FLAG_CMPx
not possible when values match"). The master sets CLR_CMPx in output byte 6 for one cycle
(``BridgeClient.set_control``); each input image afterwards decides what is sent next:
the pulse again when the image shows it never arrived (a lost RPDO), the release, or the
release once more (a lost release would leave CLR_CMPx set, and a flag that can never latch
again).
"""

from __future__ import annotations

import logging

from ssi_bridge.client.samples import ClientCounters, SlotState
from ssi_bridge.protocol.images import CmpControl, CmpStatus

logger = logging.getLogger(__name__)

#: how often a clear pulse is sent again when the next image shows it never arrived
PULSE_RESENDS = 3
#: (CLR_CMPx, FLAG_CMPx, STS_CMPx) per comparator
_PULSE_CHECKS = tuple((int(c), int(f), int(s_)) for c, f, s_ in (
    (CmpControl.CLR_CMP1, CmpStatus.FLAG_CMP1, CmpStatus.STS_CMP1),
    (CmpControl.CLR_CMP2, CmpStatus.FLAG_CMP2, CmpStatus.STS_CMP2)))


def pulse_lost(control: int, cmp: int) -> bool:
    """A requested CLR_CMPx whose FLAG_CMPx is still 1 while STS_CMPx = 0: the module would
    have carried the clear out, so the pulse RPDO never arrived.

    :param control: output byte 6 as requested (the CLR_CMPx bits)
    :param cmp: input byte 6 as received (FLAG_CMPx, STS_CMPx)
    """
    return any(control & clr and cmp & flag and not cmp & sts
               for clr, flag, sts in _PULSE_CHECKS)


def next_pulse_output(slot: int, st: SlotState, seq: int, image: bytearray,
                      counters: ClientCounters) -> bytes | None:
    """The output image to send after ``slot``'s input ``image`` of sync sequence ``seq``,
    or None.

    Call with the slot table's lock held; updates the slot's pulse state (and
    ``counters.pulse_resends``).

    :param st: the slot's state in the table (its pulse bookkeeping)
    :param counters: where a resent pulse is counted
    """
    if st.release_seq is not None and seq > st.release_seq:
        st.release_seq = None  # the release is sent once more
        return bytes(st.output)
    if st.pulse_seq is None or seq <= st.pulse_seq:
        return None
    if pulse_lost(st.output[6], image[6]) and st.pulse_resends < PULSE_RESENDS:
        # an image of a cycle after the pulse still shows FLAG_CMPx = 1 with the values not
        # matching: send the pulse again for one more cycle
        st.pulse_resends += 1
        st.pulse_seq = seq
        counters.pulse_resends += 1
        logger.info("slot %d: clear pulse not applied (lost RPDO?), sent again (%d)",
                    slot, st.pulse_resends)
        return bytes(st.output)
    st.pulse_seq = None
    st.release_seq = seq
    st.output[6] &= ~(CmpControl.CLR_CMP1 | CmpControl.CLR_CMP2) & 0xFF
    return bytes(st.output)
