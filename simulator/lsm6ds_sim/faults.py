"""Fault injection for the simulated bus and chips.

A :class:`FaultPlan` says what goes wrong and when; the simulated bus
(:class:`lsm6ds_sim.i2c.SimI2CBus`) consults its :class:`FaultInjector` before each
transaction. Faults:

- NACK / I/O-error bursts: with probability ``nack_rate`` per transaction a burst of
  ``nack_burst`` consecutive transactions fails with ``OSError(EREMOTEIO)`` (what smbus2
  raises on a NACK). A NACKed transaction has no effect on the device (the address phase
  failed).
- stuck bus: from ``stuck_bus_at_s`` for ``stuck_bus_for_s`` every transaction fails with
  ``OSError(ETIMEDOUT)``.
- spontaneous chip reset every ``reset_every_s`` (registers back to reset values).
- one forced FIFO overrun at ``overrun_at_s``.
- stuck output from ``stuck_output_at_s`` for ``stuck_output_for_s``: the sensor's
  outputs (registers and FIFO, all six axes and the temperature) repeat the last sample
  for that interval, as a hung ADC would (the timestamp keeps counting).
- reader stalls: every ``stall_every_s`` seconds, the transaction that reads the FIFO
  status (the bus's ``stall_register``) is followed by a stall of ``stall_s`` seconds
  of the calling thread (virtual clock: time jumps; wall clock: the thread sleeps), as
  a host busy elsewhere between the status and the data read would be.
- temperature glitches: Poisson events at ``temp_glitch_rate`` per second; each adds
  ``+-temp_glitch_c`` (sign drawn at random) to the temperature output for
  ``temp_glitch_s`` seconds (at least one sample): a spike on OUT_TEMP.

Random draws come from a generator seeded by ``seed`` only, so a run is reproducible.
"""

from __future__ import annotations

import errno
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from lsm6ds_sim.chip import SimChip


@dataclass
class FaultPlan:
    """What goes wrong and when (times in simulated seconds; 0 / None = never)."""

    nack_rate: float = 0.0
    nack_burst: int = 1
    stuck_bus_at_s: float | None = None
    stuck_bus_for_s: float = 0.0
    reset_every_s: float = 0.0
    overrun_at_s: float | None = None
    stuck_output_at_s: float | None = None
    stuck_output_for_s: float = 0.0
    temp_glitch_rate: float = 0.0
    temp_glitch_c: float = 5.0
    temp_glitch_s: float = 0.0
    stall_every_s: float = 0.0
    stall_s: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        for name in (
            "nack_rate",
            "stuck_bus_for_s",
            "reset_every_s",
            "stuck_output_for_s",
            "temp_glitch_rate",
            "temp_glitch_s",
            "stall_every_s",
            "stall_s",
        ):
            if getattr(self, name) < 0:
                raise ValueError(f"FaultPlan.{name}={getattr(self, name)} must be >= 0")
        if not 0.0 <= self.nack_rate <= 1.0:
            raise ValueError(f"FaultPlan.nack_rate={self.nack_rate} must be in [0, 1]")
        if self.nack_burst < 1:
            raise ValueError(f"FaultPlan.nack_burst={self.nack_burst} must be >= 1")

    @property
    def active(self) -> bool:
        return bool(
            self.nack_rate
            or self.stuck_bus_at_s is not None
            or self.reset_every_s
            or self.overrun_at_s is not None
            or self.stuck_output_at_s is not None
            or self.temp_glitch_rate
            or (self.stall_every_s and self.stall_s)
        )


class FaultInjector:
    """Applies a :class:`FaultPlan`; keeps counts of what it injected in :attr:`injected`."""

    def __init__(self, plan: FaultPlan) -> None:
        self.plan = plan
        self._rng = np.random.default_rng([plan.seed, 0x5EED])
        self._burst_left = 0
        self._next_reset_s = plan.reset_every_s if plan.reset_every_s > 0 else math.inf
        self._overrun_pending = plan.overrun_at_s is not None
        self._stuck_output_state: bool | None = None
        self._next_glitch_s = self._draw_glitch(0.0)
        self._next_stall_s = plan.stall_every_s if plan.stall_every_s > 0 else math.inf
        self.injected: dict[str, int] = {
            "stalls": 0,
            "nacks": 0,
            "stuck_bus": 0,
            "resets": 0,
            "overruns": 0,
            "temp_glitches": 0,
            "stuck_outputs": 0,
        }
        self.reset_times_s: list[float] = []

    def _draw_glitch(self, after_s: float) -> float:
        rate = self.plan.temp_glitch_rate
        return after_s + float(self._rng.exponential(1.0 / rate)) if rate > 0 else math.inf

    def before_transaction(self, now_s: float) -> None:
        """Raise the OSError a failing transaction gives, or return for a good one."""
        p = self.plan
        if (
            p.stuck_bus_at_s is not None
            and p.stuck_bus_at_s <= now_s < p.stuck_bus_at_s + p.stuck_bus_for_s
        ):
            self.injected["stuck_bus"] += 1
            raise OSError(errno.ETIMEDOUT, "Connection timed out (simulated stuck bus)")
        if self._burst_left == 0 and p.nack_rate > 0 and self._rng.random() < p.nack_rate:
            self._burst_left = p.nack_burst
        if self._burst_left > 0:
            self._burst_left -= 1
            self.injected["nacks"] += 1
            raise OSError(errno.EREMOTEIO, "Remote I/O error (simulated NACK)")

    def stall_after_read(self, now_s: float) -> float:
        """Seconds the reader stalls after the FIFO status read at ``now_s`` (0: none)."""
        if now_s < self._next_stall_s or self.plan.stall_s <= 0:
            return 0.0
        while self._next_stall_s <= now_s:
            self._next_stall_s += self.plan.stall_every_s
        self.injected["stalls"] += 1
        return self.plan.stall_s

    def apply_chip_faults(self, chip: SimChip, now_s: float) -> None:
        """Scheduled chip faults due by ``now_s``, each applied at its own time."""
        p = self.plan
        while self._next_reset_s <= now_s:
            chip.sim_advance_to(self._next_reset_s)
            chip.sim_reset()
            self.injected["resets"] += 1
            self.reset_times_s.append(self._next_reset_s)
            self._next_reset_s += p.reset_every_s
        if self._overrun_pending and p.overrun_at_s is not None and p.overrun_at_s <= now_s:
            chip.sim_advance_to(p.overrun_at_s)
            chip.sim_force_overrun()
            self._overrun_pending = False
            self.injected["overruns"] += 1
        if p.stuck_output_at_s is not None:
            start, end = p.stuck_output_at_s, p.stuck_output_at_s + p.stuck_output_for_s
            if self._stuck_output_state is None and start <= now_s:
                chip.sim_advance_to(start)
                chip.sim_stuck_output = True
                self._stuck_output_state = True
                self.injected["stuck_outputs"] += 1
            if self._stuck_output_state and end <= now_s:
                chip.sim_advance_to(end)
                chip.sim_stuck_output = False
                self._stuck_output_state = False
        while self._next_glitch_s <= now_s:
            sign = 1.0 if self._rng.random() < 0.5 else -1.0
            chip.sim_temp_glitch(sign * p.temp_glitch_c, p.temp_glitch_s, self._next_glitch_s)
            self.injected["temp_glitches"] += 1
            self._next_glitch_s = self._draw_glitch(self._next_glitch_s)
