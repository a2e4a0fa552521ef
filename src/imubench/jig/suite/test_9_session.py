"""The whole session's samples: every sample the board produced during the run, not only
those of the static capture, was delivered. A board that reset itself every 1000 s, or
lost samples to FIFO resyncs between captures, PASSed while ``fifo.lost_samples`` saw
none in its 60 s."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from imubench.jig.dut import Dut
    from imubench.jig.plugin import Measure


def test_no_sample_lost_in_the_session(dut: Dut, measure: Measure) -> None:
    tel = dut.telemetry()
    lost = int(tel["lost_samples"])  # type: ignore[call-overload]
    by_reason = tel["lost_by_reason"]
    reasons = ", ".join(f"{r}: {n}" for r, n in dict(by_reason).items())  # type: ignore[call-overload]
    measure("fifo.session_lost_samples", lost, (lost, lost), low=0, high=0,
            method=f"samples the source lost over the whole session ({tel['samples']} "
            f"delivered); by reason: {reasons or 'none'}")
