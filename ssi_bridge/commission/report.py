"""The report of a run: text for a person, a JSON object for scripts (same content).

Gateways and their identity, every slot (XN-1SSI or not), REG_PARA1 decoded, the module's
diagnostics while sampling (ERR_PARA, ERR_SSI, SSI_DIAG), what the frames showed, the
candidate families with their evidence and manual sections, and what the user must still
decide. Devices that are not an XN-GW-CANOPEN and garbage frames are reported too.
"""

from __future__ import annotations

import json
from typing import Any

from ssi_bridge.commission.analyze import SlotResult
from ssi_bridge.commission.params_out import describe_para1, joint_name
from ssi_bridge.commission.run import Result


def _slot(res: SlotResult) -> dict[str, Any]:
    p = res.decoded
    out: dict[str, Any] = {
        "node_id": res.node_id, "slot": res.slot,
        "joint": joint_name(res) if res.joint else None,
        "para1": None if res.para1 is None else f"0x{res.para1:08X}",
        "para1_object": None if res.para1_object is None else f"0x{res.para1_object:08X}",
        "para1_decoded": None if p is None else {
            "ssi_frame_len": p.ssi_frame_len, "ssi_bit_rate_hz": p.bit_rate_hz,
            "gray": p.ssi_code_gray, "invalid_bits_lsb": p.invalid_bits_lsb,
            "invalid_bits_msb": p.invalid_bits_msb, "dis_err_ssi": p.dis_err_ssi,
            "problem": p.problem()},
        "para1_joint": None if res.para1_joint is None else f"0x{res.para1_joint:08X}",
        "diagnostics": {"samples": res.samples, "frames": res.frames,
                        "err_para": round(res.err_para, 3), "err_ssi": round(res.err_ssi, 3),
                        "ssi_diag": round(res.ssi_diag, 3), "now": res.diag_now},
        "problem": res.problem, "warnings": res.warnings, "bits": res.bits,
    }
    m = res.motion
    if m is not None:
        out["motion"] = {"state": m.state.value, "lsb": m.lsb, "code": m.code,
                         "direction": m.direction, "evidence": list(m.evidence)}
    out["candidates"] = [
        [{"family": f.family, "score": f.score, "overrides": {
            k: (v.value if hasattr(v, "value") else v) for k, v in f.overrides.items()},
          "evidence": list(f.evidence), "source": f.source} for f in group]
        for group in res.groups]
    return out


def decisions(result: Result) -> list[str]:
    """What the user must still decide, one line each.

    :param result: the run's result
    """
    out = []
    for res in result.slot_results:
        if not res.joint:
            continue
        name = joint_name(res)
        if res.groups and len(res.groups[0]) > 1:
            out.append(f"{name}: the family, among "
                       f"{', '.join(f.family for f in res.groups[0])} (the frame is the same)")
        best = res.best
        if best is not None and best.config.linear:
            out.append(f"{name}: the measuring step of the linear encoder (the frame does "
                       "not show it)")
        elif best is not None and best.default_resolution:
            out.append(f"{name}: the resolution (steps per revolution): the family's default "
                       "was assumed")
        if best is not None and best.config.linear:
            out.append(f"{name}: the sign (direction) against the count")
        else:
            out.append(f"{name}: the sign (direction) against the count, and the gear ratio "
                       "if it drives a linear axis")
    return out


def as_dict(result: Result) -> dict[str, object]:
    """The report as a JSON-ready dict.

    :param result: the run's result
    :returns: the same content as :func:`as_text`, as plain JSON types
    """
    heard = result.heard
    out: dict[str, Any] = {
        "refusal": result.refusal, "listen_only": result.listen_only,
        "heartbeats": {str(k): v for k, v in sorted(heard.heartbeats.items())},
        "masters": dict(heard.masters), "garbage": dict(heard.garbage),
        "gateways": [{"node_id": st.identity.node_id, "name": st.identity.name,
                      "device_type": st.identity.device_type,
                      "revision": st.identity.revision, "serial": st.identity.serial,
                      "notes": st.identity.notes, "error": st.error,
                      "empty_slots": [{"slot": p.slot, "reason": p.absent}
                                      for p in st.probes if p.absent],
                      "slots": [_slot(s) for s in st.slots]} for st in result.stations],
        "other_devices": [{"node_id": i.node_id, "reason": i.refusal,
                           "device_type": i.device_type, "name": i.name}
                          for i in result.others],
        "silent": result.silent, "written": result.written,
        "decide": decisions(result),
    }
    obs = result.observed
    if obs is not None:
        out["observed"] = {f"{n}/{s}": {"state": m.state.value, "code": m.code,
                                        "direction": m.direction, "lsb": m.lsb}
                           for (n, s), m in obs.motions().items()}  # type: ignore[attr-defined]
    return out


def as_json(result: Result) -> str:
    """The report as JSON text.

    :param result: the run's result
    """
    return json.dumps(as_dict(result), indent=2, sort_keys=False)


def as_text(result: Result) -> str:
    """The report for a person.

    :param result: the run's result
    :returns: lines for a terminal (gateways, slots, the inferred encoders, refusals)
    """
    if result.refusal:
        return result.refusal
    lines: list[str] = []
    heard = result.heard
    if heard.garbage:
        lines.append("bus: " + ", ".join(f"{n} x {k}" for k, n in heard.garbage.items()))
    for ident in result.others:
        lines.append(f"node {ident.node_id}: {ident.refusal}")
    for text in result.silent:
        lines.append(text)
    if result.observed is not None:
        lines += _observed(result)
    for st in result.stations:
        ident = st.identity
        lines.append(f"node {ident.node_id}: XN-GW-CANOPEN (revision 0x{ident.revision or 0:08X},"
                     f" serial {ident.serial})")
        lines += [f"  note: {n}" for n in ident.notes]
        if st.error:
            lines.append(f"  {st.error}")
        empty = [p.slot for p in st.probes if p.absent]
        if empty:
            lines.append(f"  slot(s) {', '.join(map(str, empty))}: "
                         f"{st.probes[empty[0] - 1].absent}")
        for res in st.slots:
            lines += _slot_text(res)
    if not result.stations and result.observed is None:
        lines.append("no XN-GW-CANOPEN found on the bus")
    for text in result.written:
        lines.append(text)
    todo = decisions(result)
    if todo:
        lines.append("still to decide:")
        lines += [f"  - {t}" for t in todo]
    return "\n".join(lines)


def _slot_text(res: SlotResult) -> list[str]:
    p = res.decoded
    head = f"  slot {res.slot}: XN-1SSI"
    if p is not None:
        head += f", REG_PARA1 0x{p.encode():08X} ({describe_para1(p)})"
    now = ("not read" if res.diag_now is None else ", ".join(res.diag_now) or "none")
    out = [head, f"    diagnostics: ERR_PARA {res.err_para:.0%}, ERR_SSI {res.err_ssi:.0%}, "
                 f"SSI_DIAG {res.ssi_diag:.0%} of {res.samples} cycles; now (0x5804): {now}"]
    if res.problem:
        out.append(f"    no joint: {res.problem}")
        return out
    if res.bits:
        out.append(f"    frame: {res.bits}")
    if res.motion is not None:
        out.append(f"    motion: {res.motion.state.value}; " + "; ".join(res.motion.evidence))
    for rank, group in enumerate(res.groups[:3], start=1):
        for fit in group:
            out.append(f"    {rank}. {fit.family}: {'; '.join(fit.evidence)} ({fit.source})")
    out += [f"    note: {w}" for w in res.warnings]
    out.append(f"    joint {joint_name(res)}")
    return out


def _observed(result: Result) -> list[str]:
    obs = result.observed
    lines = [f"listen-only: watched {obs.seconds:g} s; gateways heard: "  # type: ignore[attr-defined]
             f"{', '.join(map(str, sorted(result.heard.heartbeats))) or 'none'}; "
             "REG_PARA1 not read (that needs the handshake): no family ranked, no params file"]
    for (node, slot), m in obs.motions().items():  # type: ignore[attr-defined]
        lines.append(f"  node {node} slot {slot}: {m.state.value}; {'; '.join(m.evidence)}")
    return lines


__all__ = ["as_dict", "as_json", "as_text", "decisions"]
