"""Noise identification and IMU noise-model fitting (issue 7; docs/noise-fit.md).

* :func:`fit_channel` fits the model file's noise terms to one channel's rate samples
  (GLS on the overlapping Allan variance with EDF weights and model selection, the
  datasheet tangent method, or GMWM) and returns a :class:`ChannelFit`;
* :func:`model_avar` is the exact sampled-data AVAR of a model channel, output filter
  included (used by ``imubench model``);
* :mod:`.identify` is the per-tau noise identification and slope table, :mod:`.units`
  the datasheet and Kalibr units.
"""

from __future__ import annotations

from imubench.noisefit.errors import FitError
from imubench.noisefit.fit import ChannelFit, fit_channel
from imubench.noisefit.model_avar import model_avar

__all__ = ["ChannelFit", "FitError", "fit_channel", "model_avar"]
