"""The chips' FIFO: word-granular storage, modes, flags and pattern index (reference §9).

Storage is a numpy array of 16-bit words, each with its position in the repeating
pattern (FIFO_STATUS3/4 report the position of the next word to be read, §9.4). Data
sets (3 words) are kept whole: an overwrite in continuous mode drops the oldest whole
data sets. Capacity 2046 words (682 data sets, 4092 bytes, §9.2).

Modes (FIFO_CTRL5[2:0], §9.3):

- bypass: FIFO disabled and emptied.
- fifo: collects until full (or until the threshold with STOP_ON_FTH), then stops;
  FIFO_FULL is set, nothing is overwritten, later data are not stored.
- continuous: when full, the newest data overwrite the oldest; OVER_RUN is set.
- continuous_to_fifo / bypass_to_continuous: switch on a trigger event
  (:meth:`Fifo.trigger`, a ``sim_`` hook of the chip).

OVER_RUN is cleared by a read that pops data or by going to bypass (exact clear timing
is ✱ in the reference).
"""

from __future__ import annotations

import numpy as np
from lsm6ds.registers import FIFO_DEPTH_WORDS, FIFO_MODES

_BYPASS = FIFO_MODES["bypass"]
_FIFO = FIFO_MODES["fifo"]
_CONT = FIFO_MODES["continuous"]
_C2F = FIFO_MODES["continuous_to_fifo"]
_B2C = FIFO_MODES["bypass_to_continuous"]


class Fifo:
    """Word FIFO with the LSM6DS modes and flags."""

    def __init__(self, capacity_words: int = FIFO_DEPTH_WORDS) -> None:
        self.capacity = capacity_words
        self._words = np.zeros(0, dtype=np.int16)
        self._pos = np.zeros(0, dtype=np.uint16)
        self.mode = _BYPASS
        self.threshold_words = 0
        self.stop_on_fth = False
        self.overrun = False
        self.triggered = False
        self.next_pattern_pos = 0
        self.lost_words = 0
        self.underflow_reads = 0

    # -- state ---------------------------------------------------------------------
    @property
    def level(self) -> int:
        """Unread words (DIFF_FIFO)."""
        return len(self._words)

    @property
    def effective_mode(self) -> int:
        """The mode that currently applies (after trigger for the two switching modes)."""
        if self.mode == _C2F:
            return _FIFO if self.triggered else _CONT
        if self.mode == _B2C:
            return _CONT if self.triggered else _BYPASS
        return self.mode

    @property
    def accepting(self) -> bool:
        return self.effective_mode != _BYPASS

    def pattern_position(self) -> int:
        """FIFO_PATTERN: pattern position of the next word a read returns."""
        return int(self._pos[0]) if len(self._pos) else self.next_pattern_pos

    def full(self) -> bool:
        return self.level + 3 > self.capacity

    def watermark(self) -> bool:
        return self.threshold_words > 0 and self.level >= self.threshold_words

    def set_mode(self, mode: int) -> None:
        if mode not in FIFO_MODES.values():
            mode = _BYPASS  # reserved codes behave as bypass
        if mode == _BYPASS:
            self.clear()
        self.mode = mode
        self.triggered = False

    def clear(self) -> None:
        self._words = self._words[:0]
        self._pos = self._pos[:0]
        self.overrun = False
        self.next_pattern_pos = 0

    def trigger(self) -> None:
        self.triggered = True

    # -- data ----------------------------------------------------------------------
    def push(self, words: np.ndarray, pos: np.ndarray) -> None:
        """Append ``words`` (int16) with their pattern positions, applying the mode."""
        if not len(words):
            return
        mode = self.effective_mode
        if mode == _BYPASS:
            return
        if mode == _FIFO:
            limit = self.capacity
            if self.stop_on_fth and self.threshold_words > 0:
                limit = min(limit, self.threshold_words)
            room = max(0, limit - self.level)
            room -= room % 3
            if room < len(words):
                self.lost_words += len(words) - room
                words, pos = words[:room], pos[:room]
        self._words = np.concatenate([self._words, words])
        self._pos = np.concatenate([self._pos, pos])
        excess = len(self._words) - self.capacity
        if excess > 0:  # continuous: overwrite the oldest whole data sets
            starts = np.nonzero(self._pos[excess:] % 3 == 0)[0]
            drop = excess + (int(starts[0]) if len(starts) else len(self._words) - excess)
            self._words = self._words[drop:]
            self._pos = self._pos[drop:]
            self.lost_words += drop
            self.overrun = True

    def pop_words(self, n: int) -> np.ndarray:
        """Remove and return the next ``n`` words; missing words read as 0 (counted)."""
        out = self._words[:n]
        self._words = self._words[n:]
        self._pos = self._pos[n:]
        if len(out):
            self.overrun = False
        if len(out) < n:
            self.underflow_reads += n - len(out)
            out = np.concatenate([out, np.zeros(n - len(out), dtype=np.int16)])
        return out

    def drop_all(self) -> int:
        """Discard the content as an overrun would (forced overrun); returns words lost."""
        n = self.level
        self._words = self._words[:0]
        self._pos = self._pos[:0]
        self.lost_words += n
        self.overrun = True
        return n
