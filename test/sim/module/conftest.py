"""Fixtures for the module stage: a scripted SsiReader, a module on it, a process-data master."""

from __future__ import annotations

from collections import deque
from dataclasses import replace

import pytest

from ssi_bridge.protocol.readout import LineReadout
from ssi_bridge.protocol.images import CmpControl, ProcessInput, ProcessOutput
from ssi_bridge.sim.module.xn1ssi import Xn1Ssi


class ScriptedReader:
    """An SsiReader returning chosen frames; the last one repeats when the script runs out."""

    def __init__(self) -> None:
        self.script: deque[tuple[int, int, int]] = deque()
        self.last = (0, 0, 1)
        self.calls: list[tuple[float, int, float]] = []

    def push(self, data: int, *, trailer_bit: int = 0, start_bit: int = 1) -> ScriptedReader:
        self.script.append((data, trailer_bit, start_bit))
        return self

    def read(self, t: float, n_bits: int, bit_rate_hz: float) -> LineReadout:
        self.calls.append((t, n_bits, bit_rate_hz))
        if self.script:
            self.last = self.script.popleft()
        data, trailer, start = self.last
        return LineReadout(latch_time=t, n_bits=n_bits, data=data & ((1 << n_bits) - 1),
                           start_bit=start, trailer_bit=trailer,
                           end_time=t + (n_bits + 1) / bit_rate_hz)


class Master:
    """Drives a module through its process images only, on an injected clock (t += dt)."""

    def __init__(self, module: Xn1Ssi, dt: float = 0.001) -> None:
        self.module = module
        self.t = 0.0
        self.dt = dt
        self.out = ProcessOutput()

    def cycle(self, **changes: object) -> ProcessInput:
        """Set fields of the process output image, run one cycle, return the process input."""
        if changes:
            self.out = replace(self.out, **changes)  # type: ignore[arg-type]
        self.module.set_process_output(self.out.encode())
        self.module.cycle(self.t)
        self.t += self.dt
        return ProcessInput.decode(self.module.process_input())

    def control(self, *flags: CmpControl) -> ProcessInput:
        cmp = CmpControl(0)
        for f in flags:
            cmp |= f
        return self.cycle(cmp=cmp)

    def write(self, addr: int, value: int) -> ProcessInput:
        """The full 000 write handshake; returns the image that carried REG_WR_AKN = 1."""
        idle = self.cycle(reg_wr=False)
        assert not idle.reg_wr_akn, f"REG_WR_AKN still 1 with REG_WR = 0: {idle}"
        ack = self.cycle(reg_wr=True, reg_wr_adr=addr, reg_wr_data=value)
        assert ack.reg_wr_akn, f"no REG_WR_AKN after REG_WR = 1 for 0x{addr:02X}: {ack}"
        done = self.cycle(reg_wr=False)
        assert not done.reg_wr_akn, f"REG_WR_AKN not cleared by REG_WR = 0: {done}"
        return ack

    def read(self, addr: int) -> ProcessInput:
        return self.cycle(reg_rd_adr=addr)


@pytest.fixture
def reader() -> ScriptedReader:
    return ScriptedReader()


@pytest.fixture
def module(reader: ScriptedReader) -> Xn1Ssi:
    return Xn1Ssi(reader)


@pytest.fixture
def master(module: Xn1Ssi) -> Master:
    return Master(module)
