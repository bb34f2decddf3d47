"""What each family's manual allows: its transmit codes, and the TR limits on data bits and frames.

:class:`~ssi_bridge.protocol.encoder_config.EncoderConfig` checks a config named after a
family (``families.py``) against these rules on construction, and the joint parameters the
node and the ``station`` program share (``settings.py``) check ``<joint>.code`` with them, so
every place that accepts a layout refuses what the manual does not offer, in the manual's
words.

Codes per family (the section that says so):

* GENERIC: 000 ch. 1 "Gray code or binary code data transmission is possible", Table 19
  SSI_CODE_G/D — the XN-1SSI decodes nothing else;
* AHS36 / AHM36_MULTI: 004 §3.1 "SSI Code Type: Gray, Binary", "either Gray-coded or binary
  coded";
* ATM60 / ATM90 / ATM60_13_12: 004 §3.4 round axis, "The various code types such as binary,
  Gray or Gray excess can be set for this" (Tannenbaum: binary or Gray, ``EncoderConfig``);
* TR_PROGRAMMABLE / TR_PARITY: 001 §5.2.2 "Transmit code: Binary, Gray, BCD"; TR_CHECKSUM:
  001 §5.2.4.2 "28 Datenbits ohne SSI-Sonderbits im Binärcode" (the English pages lost it);
* SSI25_POWERFAIL: 003 "Coding (e.g. Gray code)", read by masters that decode binary or Gray
  (003 EL500x, 000 Table 19);
* AFS60, AFM60_MULTI, AFS60S_PRO, AFM60S_PRO, ARS60, TTK70, KH53: their sections (004 §3.2,
  §3.3, §3.5-§3.7) name no code. Binary and Gray are taken as offered (004 §2.4: SSI encoders
  "preferentially use the Gray code"; binary is the presets' default); Gray-excess or BCD
  only under the explicit ``EncoderConfig.code_outside_manual`` (docs/encoder_line.md).
"""

from __future__ import annotations

from dataclasses import dataclass

from ssi_bridge.protocol.codes import Code


@dataclass(frozen=True)
class CodeRule:
    """The transmit codes a family's manual offers, and where it says so."""

    #: codes the manual offers, in its order
    codes: tuple[Code, ...]
    #: the manual's words and section
    source: str
    #: the family's section names no code: others only with ``code_outside_manual``
    silent: bool = False

    def names(self) -> str:
        """The offered codes as the ``<joint>.code`` / :class:`Code` values, comma-separated."""
        return ", ".join(code.value for code in self.codes)


_BG = (Code.BINARY, Code.GRAY)
_SICK_SILENT = CodeRule(_BG, "004 §3.2-§3.7 name no code for this family; 004 §2.4: SSI "
                             "encoders 'preferentially use the Gray code'", silent=True)
_AHM36 = CodeRule(_BG, "004 §3.1 'SSI Code Type: Gray, Binary'")
_ATM60 = CodeRule((Code.BINARY, Code.GRAY, Code.GRAY_EXCESS),
                  "004 §3.4 'The various code types such as binary, Gray or Gray excess can be "
                  "set for this'")
_TR = CodeRule((Code.BINARY, Code.GRAY, Code.BCD),
               "001 §5.2.2 'Transmit code: Binary, Gray, BCD'")

#: the codes each family's manual offers (families.py names)
FAMILY_CODES: dict[str, CodeRule] = {
    "GENERIC": CodeRule(_BG, "000 ch. 1 'Gray code or binary code data transmission is "
                             "possible' (Table 19 SSI_CODE_G/D)"),
    "AHS36": _AHM36, "AHM36_MULTI": _AHM36,
    "AFS60": _SICK_SILENT, "AFM60_MULTI": _SICK_SILENT,
    "AFS60S_PRO": _SICK_SILENT, "AFM60S_PRO": _SICK_SILENT,
    "ATM60": _ATM60, "ATM90": _ATM60, "ATM60_13_12": _ATM60,
    "ARS60": _SICK_SILENT, "TTK70": _SICK_SILENT, "KH53": _SICK_SILENT,
    "TR_PROGRAMMABLE": _TR, "TR_PARITY": _TR,
    "TR_CHECKSUM": CodeRule((Code.BINARY,), "001 §5.2.4.2 '28 Datenbits ohne SSI-Sonderbits "
                                            "im Binärcode' (28 data bits in binary code)"),
    "SSI25_POWERFAIL": CodeRule(_BG, "003 'Coding (e.g. Gray code)', read by masters that "
                                     "decode binary or Gray (000 Table 19)"),
}

#: the TR-Electronic encoders of 001, whose "Number of data bits" and frame limits apply
TR_FAMILIES = frozenset({"TR_PROGRAMMABLE", "TR_PARITY", "TR_CHECKSUM"})
#: 001 §5.2.1 "Number of data bits": lower limit 6, upper limit 63
TR_DATA_BITS = (6, 63)
#: 001 §5.2.4.1 "No special format": a transmission of 8 to 36 bits
TR_PLAIN_FRAME_BITS = (8, 36)
TR_DATA_BITS_WORDS = "001 §5.2.1 'Number of data bits': lower limit 6, upper limit 63"
TR_PLAIN_FRAME_WORDS = ("001 §5.2.4.1: 'A synchronous-serial data transmission with No special "
                        "format is min. 8 bits, or max. 36 bits long'")


def code_refusal(family: str, code: Code, *, code_outside_manual: bool = False) -> str | None:
    """Why ``family``'s manual does not offer ``code`` (with the list it offers), or None.

    None also for a name that is no family (a hand-made layout) and, for a family whose
    section names no code, for any code under ``code_outside_manual``.
    """
    rule = FAMILY_CODES.get(family.upper())
    if rule is None or code in rule.codes or (rule.silent and code_outside_manual):
        return None
    hint = (" (code_outside_manual allows another code for this family)" if rule.silent
            else "")
    return (f"transmit code {code.value!r} is not offered for {family.upper()}: {rule.source}; "
            f"offered: {rule.names()}{hint}")


__all__ = ["CodeRule", "FAMILY_CODES", "TR_DATA_BITS", "TR_DATA_BITS_WORDS", "TR_FAMILIES",
           "TR_PLAIN_FRAME_BITS", "TR_PLAIN_FRAME_WORDS", "code_refusal"]
