"""The 8-byte process input and output images of the XN-1SSI (000 ch. 2, PROFIBUS-DP data image).

Byte order: bytes 0-3 carry REG_RD_DATA / REG_WR_DATA with byte 0 = data byte 3 (the most
significant byte) and byte 3 = data byte 0, i.e. big-endian, exactly as the PROFIBUS-DP
tables show ("Byte 0: REG_RD_DATA, Byte 3 ... Byte 3: REG_RD_DATA, Byte 0").  The same
8 bytes travel unchanged through the gateway.  Reserved (X) bits are ignored on decode and
sent as 0 on encode.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import IntFlag

#: 8-byte image: 32-bit data big-endian, then bytes 4, 5, 6, 7
IMAGE_STRUCT = struct.Struct(">IBBBB")
IMAGE_SIZE = IMAGE_STRUCT.size
#: 6-bit register address field of bytes 4 and 5 (0..63)
ADDRESS_MASK = 0x3F


class ReadStatus(IntFlag):
    """Process input byte 4 (bits 5..0 hold REG_RD_ADR, bit 6 reserved)."""

    REG_RD_ABORT = 0x80


class WriteStatus(IntFlag):
    """Process input byte 5: write handshake and SSI encoder status bits."""

    SSI_STS0 = 0x01
    SSI_STS1 = 0x02
    SSI_STS2 = 0x04
    SSI_STS3 = 0x08
    REG_WR_AKN = 0x40
    REG_WR_ACCEPT = 0x80


class CmpStatus(IntFlag):
    """Process input byte 6: comparators and direction."""

    STS_CMP1 = 0x01
    FLAG_CMP1 = 0x02
    REL_CMP1 = 0x04
    STS_CMP2 = 0x08
    FLAG_CMP2 = 0x10
    REL_CMP2 = 0x20
    STS_DN = 0x40
    STS_UP = 0x80


class ModuleStatus(IntFlag):
    """Process input byte 7: communication status and limit results (bits 5, 6 reserved)."""

    SSI_DIAG = 0x01
    ERR_SSI = 0x02
    STS_OFLW = 0x04
    STS_UFLW = 0x08
    ERR_PARA = 0x10
    STS_STOP = 0x80


class WriteRequest(IntFlag):
    """Process output byte 5 (bits 5..0 hold REG_WR_ADR, bit 6 reserved)."""

    REG_WR = 0x80


class CmpControl(IntFlag):
    """Process output byte 6: comparator enables and flag resets (bits 2, 5..7 reserved)."""

    EN_CMP1 = 0x01
    CLR_CMP1 = 0x02
    EN_CMP2 = 0x08
    CLR_CMP2 = 0x10


class Control(IntFlag):
    """Process output byte 7 (bits 6..0 reserved)."""

    STOP = 0x80


_SSI_STS_MASK = 0x0F
_CMP_STATUS_ALL = CmpStatus(0xFF)
_MODULE_STATUS_ALL = ModuleStatus(0x9F)
_CMP_CONTROL_ALL = CmpControl(0x1B)


# the same bits as plain ints, for encode_input (run by the module on every cycle)
_RD_ABORT = int(ReadStatus.REG_RD_ABORT)
_WR_AKN, _WR_ACCEPT = int(WriteStatus.REG_WR_AKN), int(WriteStatus.REG_WR_ACCEPT)
_CMP_BYTE, _STS_BYTE = int(_CMP_STATUS_ALL), int(_MODULE_STATUS_ALL)


def encode_input(reg_rd_data: int, reg_rd_adr: int, reg_rd_abort: bool, reg_wr_akn: bool,
                 reg_wr_accept: bool, ssi_sts: int, cmp: int, sts: int) -> bytes:
    """Process input image from its fields as ints (000 "Process input").

    The one encoder of the image: :meth:`ProcessInput.encode` and the module's cycle, which
    keeps its state as ints, both use it; plain int arithmetic, because an ``IntFlag``
    operation is a Python-level call.  Reserved bits are sent as 0.

    :param reg_rd_data: REG_RD_DATA (bytes 0-3)
    :param reg_rd_adr: REG_RD_ADR (byte 4, bits 0-5)
    :param reg_rd_abort: REG_RD_ABORT
    :param reg_wr_akn: REG_WR_AKN
    :param reg_wr_accept: REG_WR_ACCEPT
    :param ssi_sts: the SSI status bits of byte 5
    :param cmp: the comparator bits of byte 6
    :param sts: the status bits of byte 7
    :returns: the 8-byte image
    """
    return IMAGE_STRUCT.pack(
        reg_rd_data & 0xFFFFFFFF,
        (reg_rd_adr & ADDRESS_MASK) | (_RD_ABORT if reg_rd_abort else 0),
        (ssi_sts & _SSI_STS_MASK) | (_WR_AKN if reg_wr_akn else 0)
        | (_WR_ACCEPT if reg_wr_accept else 0),
        cmp & _CMP_BYTE, sts & _STS_BYTE)


def _check_len(image: bytes) -> None:
    if len(image) != IMAGE_SIZE:
        raise ValueError(f"process image must be {IMAGE_SIZE} bytes, got {len(image)}")


@dataclass(frozen=True)
class ProcessInput:
    """Process input image (module -> master), 000 "Process input"."""

    #: REG_RD_DATA: content of register REG_RD_ADR, 0 if REG_RD_ABORT = 1
    reg_rd_data: int = 0
    #: REG_RD_ADR: address echo of the read (0..63)
    reg_rd_adr: int = 0
    #: REG_RD_ABORT: the read of REG_RD_ADR was not accepted
    reg_rd_abort: bool = False
    #: REG_WR_AKN: a write was initiated by REG_WR = 1; cleared when REG_WR returns to 0
    reg_wr_akn: bool = False
    #: REG_WR_ACCEPT: the acknowledged write was executed successfully
    reg_wr_accept: bool = False
    #: SSI_STS3..0 as a 4-bit number (bit x = SSI_STSx)
    ssi_sts: int = 0
    #: byte 6
    cmp: CmpStatus = CmpStatus(0)
    #: byte 7
    sts: ModuleStatus = ModuleStatus(0)

    def encode(self) -> bytes:
        """The 8 bytes as the gateway transports them."""
        return encode_input(self.reg_rd_data, self.reg_rd_adr, self.reg_rd_abort,
                            self.reg_wr_akn, self.reg_wr_accept, self.ssi_sts, int(self.cmp),
                            int(self.sts))

    @classmethod
    def decode(cls, image: bytes) -> ProcessInput:
        """Parse 8 bytes; raises ValueError for another length.

        :param image: the 8 bytes of object 0x2000
        :raises ValueError: ``image`` is not 8 bytes long
        """
        _check_len(image)
        data, byte4, byte5, byte6, byte7 = IMAGE_STRUCT.unpack(image)
        return cls(
            reg_rd_data=data,
            reg_rd_adr=byte4 & ADDRESS_MASK,
            reg_rd_abort=bool(byte4 & ReadStatus.REG_RD_ABORT),
            reg_wr_akn=bool(byte5 & WriteStatus.REG_WR_AKN),
            reg_wr_accept=bool(byte5 & WriteStatus.REG_WR_ACCEPT),
            ssi_sts=byte5 & _SSI_STS_MASK,
            cmp=CmpStatus(byte6),
            sts=ModuleStatus(byte7) & _MODULE_STATUS_ALL,
        )

    def bits(self) -> dict[str, int]:
        """Every named bit (and the multi-bit fields) by its manual name, for status topics."""
        out: dict[str, int] = {"REG_RD_DATA": self.reg_rd_data, "REG_RD_ADR": self.reg_rd_adr,
                               "REG_RD_ABORT": int(self.reg_rd_abort),
                               "REG_WR_AKN": int(self.reg_wr_akn),
                               "REG_WR_ACCEPT": int(self.reg_wr_accept)}
        for i in range(4):
            out[f"SSI_STS{i}"] = self.ssi_sts >> i & 1
        for flag in CmpStatus:
            out[str(flag.name)] = int(flag in self.cmp)
        for bit in ModuleStatus:
            out[str(bit.name)] = int(bit in self.sts)
        return out


@dataclass(frozen=True)
class ProcessOutput:
    """Process output image (master -> module), 000 "Process output"."""

    #: REG_WR_DATA: value for register REG_WR_ADR
    reg_wr_data: int = 0
    #: REG_RD_ADR: register to read with the next process input (0..63)
    reg_rd_adr: int = 0
    #: REG_WR_ADR: register to write (0..63)
    reg_wr_adr: int = 0
    #: REG_WR: write request
    reg_wr: bool = False
    #: byte 6: EN_CMPx / CLR_CMPx
    cmp: CmpControl = CmpControl(0)
    #: STOP: interrupt communication with the encoder
    stop: bool = False

    def encode(self) -> bytes:
        """The 8 bytes as the master sends them."""
        byte5 = (self.reg_wr_adr & ADDRESS_MASK) | (WriteRequest.REG_WR if self.reg_wr else 0)
        return IMAGE_STRUCT.pack(self.reg_wr_data & 0xFFFFFFFF, self.reg_rd_adr & ADDRESS_MASK,
                                 int(byte5), int(self.cmp & _CMP_CONTROL_ALL),
                                 int(Control.STOP) if self.stop else 0)

    @classmethod
    def decode(cls, image: bytes) -> ProcessOutput:
        """Parse 8 bytes, ignoring reserved bits; raises ValueError for another length.

        :param image: the 8 bytes of object 0x2100
        :raises ValueError: ``image`` is not 8 bytes long
        """
        _check_len(image)
        data, byte4, byte5, byte6, byte7 = IMAGE_STRUCT.unpack(image)
        return cls(
            reg_wr_data=data,
            reg_rd_adr=byte4 & ADDRESS_MASK,
            reg_wr_adr=byte5 & ADDRESS_MASK,
            reg_wr=bool(byte5 & WriteRequest.REG_WR),
            cmp=CmpControl(byte6) & _CMP_CONTROL_ALL,
            stop=bool(byte7 & Control.STOP),
        )
