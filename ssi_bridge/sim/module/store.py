"""Retentive storage of the XN-1SSI register bank (000 interface table, "Storage in module").

The retentive registers (REG_PARA1, REG_LOWER_LIMIT, REG_UPPER_LIMIT, REG_OFFSET,
REG_SSI_MASK) and their write counters (000: "Retentive registers can be written up to
100,000 times") are kept in one small JSON file.  A save writes a temporary file in the same
directory, fsyncs it, and renames it over the bank with ``os.replace`` (atomic on POSIX), then
fsyncs the directory: a crash at any point leaves either the old or the new bank, never a
mix.  A CRC-32 over the payload catches a file damaged by other means; such a file raises
:class:`StorageError` instead of silently loading defaults.  One writer per file.
"""

from __future__ import annotations

import json
import logging
import os
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Protocol

from ssi_bridge.exceptions import StorageError
from ssi_bridge.protocol.registers import REGISTERS, RETENTIVE, VALUE_MAX, Reg

logger = logging.getLogger(__name__)

#: file format tag and version written into every bank file
BANK_FORMAT = "ssi_bridge.sim.module.bank"
BANK_VERSION = 1


def _defaults() -> dict[Reg, int]:
    return {reg: REGISTERS[reg].default for reg in RETENTIVE}


@dataclass(frozen=True)
class BankSnapshot:
    """The retentive part of one module's register bank plus the write counters."""

    #: value of every retentive register
    values: Mapping[Reg, int] = field(default_factory=_defaults)
    #: accepted writes per retentive register since the bank was new (endurance model)
    write_counts: Mapping[Reg, int] = field(default_factory=dict)

    def encode(self) -> bytes:
        """Serialise as JSON with a CRC-32 of the canonical payload."""
        payload = {
            "registers": {reg.name: int(self.values[reg]) for reg in RETENTIVE},
            "write_counts": {reg.name: int(self.write_counts.get(reg, 0)) for reg in RETENTIVE},
        }
        crc = zlib.crc32(json.dumps(payload, sort_keys=True).encode())
        doc = {"format": BANK_FORMAT, "version": BANK_VERSION, "crc32": crc, **payload}
        return (json.dumps(doc, sort_keys=True, indent=1) + "\n").encode()

    @classmethod
    def decode(cls, data: bytes, source: str = "<bytes>") -> BankSnapshot:
        """Parse a bank file; raises StorageError naming what is wrong.

        :param data: the file's bytes
        :param source: the file's name, for the message
        """
        try:
            doc = json.loads(data.decode())
            if doc.get("format") != BANK_FORMAT or doc.get("version") != BANK_VERSION:
                raise ValueError(f"not a version {BANK_VERSION} {BANK_FORMAT} file")
            payload = {"registers": doc["registers"], "write_counts": doc["write_counts"]}
            if zlib.crc32(json.dumps(payload, sort_keys=True).encode()) != doc["crc32"]:
                raise ValueError("CRC-32 mismatch")
            values = {reg: _checked(doc["registers"][reg.name], reg.name) for reg in RETENTIVE}
            counts = {reg: _checked(doc["write_counts"][reg.name], reg.name) for reg in RETENTIVE}
        except (ValueError, KeyError, TypeError, AttributeError) as err:
            raise StorageError(f"retentive bank {source} unreadable: {err}") from err
        return cls(values, counts)


def _checked(value: object, name: str) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or not 0 <= value <= VALUE_MAX:
        raise ValueError(f"{name} = {value!r} is not a 32-bit unsigned integer")
    return value


class BankStore(Protocol):
    """Where a module keeps its retentive registers."""

    def load(self) -> BankSnapshot | None:
        """The stored bank, or None if nothing was stored yet."""
        ...

    def save(self, snapshot: BankSnapshot) -> None:
        """Store ``snapshot`` completely or not at all (raises StorageError)."""
        ...


class MemoryStore:
    """A bank kept in memory: survives a module object being rebuilt, not the process.

    :param snapshot: the bank to start with (None: none stored yet)
    """

    def __init__(self, snapshot: BankSnapshot | None = None) -> None:
        self.snapshot = snapshot
        self.saves = 0

    def load(self) -> BankSnapshot | None:
        """The bank saved last, or None."""
        return self.snapshot

    def save(self, snapshot: BankSnapshot) -> None:
        """Keep ``snapshot`` as the bank (counted in ``saves``)."""
        self.snapshot = snapshot
        self.saves += 1


class RetentiveStore:
    """A bank file at ``path`` (configurable per slot), replaced atomically on every save.

    :param path: the bank file
    :param fsync: fsync each save before the replace (the simulated station passes False)
    """

    def __init__(self, path: str | os.PathLike[str], *, fsync: bool = True) -> None:
        self.path = Path(path)
        self.fsync = fsync

    def _tmp_glob(self) -> str:
        return f".{self.path.name}.*.tmp"

    def load(self) -> BankSnapshot | None:
        """Read the bank (None if there is no file); remove temp files a crash left behind.

        :raises StorageError: the file cannot be read or is not a valid bank
        """
        for stale in self.path.parent.glob(self._tmp_glob()):
            logger.info("removing %s left by an interrupted save", stale)
            stale.unlink(missing_ok=True)
        try:
            data = self.path.read_bytes()
        except FileNotFoundError:
            return None
        except OSError as err:
            raise StorageError(f"cannot read retentive bank {self.path}: {err}") from err
        return BankSnapshot.decode(data, str(self.path))

    def save(self, snapshot: BankSnapshot) -> None:
        """Write the bank to a temp file, fsync, ``os.replace`` it over the old one.

        :param snapshot: the bank
        :raises StorageError: the file cannot be written (the old one is kept)
        """
        data = snapshot.encode()
        tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.tmp")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            with open(tmp, "wb") as fh:
                fh.write(data)
                fh.flush()
                if self.fsync:
                    os.fsync(fh.fileno())
            os.replace(tmp, self.path)
            if self.fsync:
                dir_fd = os.open(self.path.parent, os.O_RDONLY)
                try:
                    os.fsync(dir_fd)
                finally:
                    os.close(dir_fd)
        except OSError as err:
            tmp.unlink(missing_ok=True)
            raise StorageError(f"cannot store retentive bank {self.path}: {err}") from err
