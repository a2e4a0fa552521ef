"""Measurements and their verdicts (the idea of OpenHTF's measurements and validators).

A measurement is a name, a value, a unit, limits ``[low, high]`` (either may be open)
and the value's confidence interval ``[ci_low, ci_high]`` at the run's confidence level
(an exact quantity, such as a count or a register value, has ``ci_low = ci_high =
value``). The verdict never lets a noisy estimate pass silently:

* PASS when the whole confidence interval lies inside the limits,
* FAIL when it lies wholly outside them,
* INCONCLUSIVE otherwise (the interval straddles a limit, or could not be computed).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

PASS = "PASS"
FAIL = "FAIL"
INCONCLUSIVE = "INCONCLUSIVE"
VERDICTS = (PASS, FAIL, INCONCLUSIVE)


def judge(ci_low: float, ci_high: float, low: float | None, high: float | None) -> str:
    """PASS, FAIL or INCONCLUSIVE of an interval against limits (module docstring)."""
    if not (math.isfinite(ci_low) and math.isfinite(ci_high)) or ci_low > ci_high:
        return INCONCLUSIVE
    if (low is not None and ci_high < low) or (high is not None and ci_low > high):
        return FAIL
    if (low is None or ci_low >= low) and (high is None or ci_high <= high):
        return PASS
    return INCONCLUSIVE


def overall(verdicts: list[str]) -> str:
    """FAIL if any measurement failed, else INCONCLUSIVE if any was, else PASS."""
    if FAIL in verdicts:
        return FAIL
    if INCONCLUSIVE in verdicts:
        return INCONCLUSIVE
    return PASS


@dataclass(frozen=True)
class Measurement:
    """One judged measurement (JSON keys are the field names; the MQTT payload carries
    ``name value unit low high ci_low ci_high verdict``)."""

    name: str
    value: float
    unit: str
    low: float | None
    high: float | None
    ci_low: float
    ci_high: float
    verdict: str
    method: str = ""
    test: str = ""

    @classmethod
    def judged(cls, name: str, value: float, unit: str, low: float | None, high: float | None,
               ci: tuple[float, float], method: str = "", test: str = "") -> Measurement:
        lo, hi = float(ci[0]), float(ci[1])
        return cls(name, float(value), unit, low, high, lo, hi, judge(lo, hi, low, high),
                   method, test)

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self)
        for k in ("value", "ci_low", "ci_high"):
            if not math.isfinite(d[k]):
                d[k] = None
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Measurement:
        nan = float("nan")
        return cls(d["name"], nan if d["value"] is None else d["value"], d["unit"], d["low"],
                   d["high"], nan if d["ci_low"] is None else d["ci_low"],
                   nan if d["ci_high"] is None else d["ci_high"], d["verdict"],
                   d.get("method", ""), d.get("test", ""))

    def describe(self) -> str:
        lim = f"[{'-inf' if self.low is None else f'{self.low:g}'}, "
        lim += f"{'inf' if self.high is None else f'{self.high:g}'}]"
        return (f"{self.name} = {self.value:.6g} {self.unit} (CI {self.ci_low:.6g} .."
                f" {self.ci_high:.6g}, limits {lim}): {self.verdict}")


__all__ = ["FAIL", "INCONCLUSIVE", "PASS", "VERDICTS", "Measurement", "judge", "overall"]
