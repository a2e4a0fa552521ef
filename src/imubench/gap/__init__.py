"""Sim-to-real gap diagnosis (``imubench gap``): where, which effect, how far, held out.

See ``docs/gap.md``. :func:`diagnose_channel` does one channel; :func:`diagnose_recording`
does the channels of a recording and returns the JSON structure of the issue's contract.
"""

from __future__ import annotations

from imubench.gap.candidates import EFFECTS, MAIN_PARAM
from imubench.gap.diagnose import diagnose_channel
from imubench.gap.errors import GapError
from imubench.gap.parts import Series
from imubench.gap.recording import diagnose_recording, series_of
from imubench.gap.result import ChannelDiagnosis, GapOptions

__all__ = [
    "EFFECTS", "MAIN_PARAM", "ChannelDiagnosis", "GapError", "GapOptions", "Series",
    "diagnose_channel", "diagnose_recording", "series_of",
]
