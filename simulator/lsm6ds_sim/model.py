"""The sensor noise model and its TOML file.

The file is the contract between the simulator, the noise fit (``imubench fit`` writes it)
and the sim-to-real diagnosis (which copies a model, changes a term, and re-simulates)::

    [meta]                   # optional, free-form provenance (strings, numbers, booleans)
    name = "LSM6DSL typical"

    [defaults]               # optional, applies to every channel
    [channels.gx]            # gx gy gz in dps, ax ay az in g; omitted keys are zero
    white = 0.004            # N, unit/sqrt(Hz)        AVAR N^2/tau
    flicker = 0.0005         # B, unit                 AVAR (2 ln2/pi) B^2
    random_walk = 0.0        # K, unit/sqrt(s)         AVAR K^2 tau/3
    ramp = 0.0               # R, unit/s               AVAR R^2 tau^2/2
    quantization = 0.0       # Q, unit*s               AVAR 3 Q^2/tau^2
    markov_sigma = 0.0       # unit, stationary std of a first-order Gauss-Markov process
    markov_tau = 0.0         # s, its correlation time
    sine_amplitude = 0.0     # unit, peak
    sine_freq = 0.0          # Hz
    resonance_freq_hz = 0.0  # Hz, centre of a narrowband resonance (Lorentzian line)
    resonance_width_hz = 0.0 # Hz, its -3 dB width
    resonance_height = 0.0   # unit^2/Hz, its peak one-sided PSD above the continuum
    outlier_rate = 0.0       # impulses per second
    outlier_amplitude = 0.0  # unit, standard deviation of an impulse
    bias = 0.0               # unit
    temp_coeff = 0.0         # unit/degC
    temp_coeff2 = 0.0        # unit/degC^2
    temp_ref = 25.0          # degC

Extension keys (documented in ``docs/noise-model.md``; a file without them loads the
same): ``bandwidth_hz`` and ``filter_order`` (output low-pass), ``output_white`` (white
noise after that filter), ``scale_error``,
``scale_temp_coeff``, ``scale_temp_coeff2``, ``nonlinearity``, ``cross_x``/``cross_y``/
``cross_z`` and, on gyro channels, ``g_sensitivity_x``/``_y``/``_z``.

Rules: unknown tables and keys are errors; noise magnitudes (and rates, times,
frequencies, bandwidths) must be >= 0; ``bias``, ``ramp``, temperature and sensitivity
coefficients are signed. Every error is a :class:`imubench.errors.ModelError` naming the
file, the table, the key and, when it can be found, the line.
"""

from __future__ import annotations

import dataclasses
import math
import re
import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, fields
from importlib import resources
from importlib.resources.abc import Traversable
from pathlib import Path
from typing import Any

import tomli_w
from lsm6ds.channels import CHANNELS

from lsm6ds_sim.errors import ModelError

GYRO_CHANNELS: tuple[str, ...] = ("gx", "gy", "gz")
ACCEL_CHANNELS: tuple[str, ...] = ("ax", "ay", "az")

NON_NEGATIVE_KEYS: frozenset[str] = frozenset(
    {
        "white",
        "flicker",
        "random_walk",
        "quantization",
        "markov_sigma",
        "markov_tau",
        "sine_amplitude",
        "sine_freq",
        "resonance_freq_hz",
        "resonance_width_hz",
        "resonance_height",
        "outlier_rate",
        "outlier_amplitude",
        "bandwidth_hz",
        "output_white",
    }
)
"""Keys that are magnitudes, rates, times or frequencies: negative values are errors."""

_KEY_RE_CACHE: dict[str, re.Pattern[str]] = {}


@dataclass(frozen=True)
class ChannelModel:
    """Noise terms and sensor errors of one channel (units: dps for gyro, g for accel).

    Every field is a key of the model file; see the module docstring for units and the
    Allan-variance contribution of each noise term (IEEE Std 952-1997 Annex C,
    El-Sheimy et al. 2008 Table 1).
    """

    white: float = 0.0
    flicker: float = 0.0
    random_walk: float = 0.0
    ramp: float = 0.0
    quantization: float = 0.0
    markov_sigma: float = 0.0
    markov_tau: float = 0.0
    sine_amplitude: float = 0.0
    sine_freq: float = 0.0
    resonance_freq_hz: float = 0.0
    """Centre (Hz) of the narrowband resonance; below the output's Nyquist frequency
    (checked when simulating)."""
    resonance_width_hz: float = 0.0
    """-3 dB width (Hz) of the resonance's Lorentzian line (lsm6ds_sim.noise.resonance_pole)."""
    resonance_height: float = 0.0
    """Peak one-sided PSD (unit^2/Hz) the resonance adds at its centre; 0 = no resonance."""
    outlier_rate: float = 0.0
    outlier_amplitude: float = 0.0
    bias: float = 0.0
    temp_coeff: float = 0.0
    temp_coeff2: float = 0.0
    temp_ref: float = 25.0
    # --- extensions (see docs/noise-model.md) ---
    bandwidth_hz: float = 0.0
    """-3 dB bandwidth of the output low-pass (Butterworth, bilinear); 0 = no filter."""
    filter_order: int = 1
    """Order of the output low-pass: 1 or 2."""
    output_white: float = 0.0
    """White noise density (unit/sqrt(Hz)) added *after* the output low-pass (ADC and
    quantisation noise of a real sensor); AVAR N^2/tau, like ``white`` without a filter."""
    scale_error: float = 0.0
    """Sensitivity error, fraction (output = (1 + scale_error) * input)."""
    scale_temp_coeff: float = 0.0
    """Sensitivity change per degC (fraction/degC) about temp_ref."""
    scale_temp_coeff2: float = 0.0
    """Sensitivity change per degC^2 (fraction/degC^2) about temp_ref."""
    nonlinearity: float = 0.0
    """Quadratic nonlinearity k2 in 1/unit: input u reads as u + k2 u^2."""
    cross_x: float = 0.0
    """Cross-axis coupling (fraction) from the same sensor's X input."""
    cross_y: float = 0.0
    cross_z: float = 0.0
    g_sensitivity_x: float = 0.0
    """Gyro only: rate error per g of specific force along sensor X (dps/g)."""
    g_sensitivity_y: float = 0.0
    g_sensitivity_z: float = 0.0

    def replace(self, **overrides: float) -> ChannelModel:
        """A copy with some keys changed (validated like a file)."""
        return _channel_from_table({**self.to_dict(), **overrides}, "<replace>", "channel")

    def to_dict(self) -> dict[str, float]:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @property
    def is_quiet(self) -> bool:
        """True when the channel adds no noise, offset or error at all."""
        base = ChannelModel(temp_ref=self.temp_ref, filter_order=self.filter_order)
        return self == base


KEYS: tuple[str, ...] = tuple(f.name for f in fields(ChannelModel))
"""Every key a channel table may carry."""
_INT_KEYS = frozenset({"filter_order"})


@dataclass(frozen=True)
class NoiseModel:
    """A noise model for the six channels ``gx gy gz ax ay az``.

    Immutable; copy-and-modify with :meth:`with_channel`, :meth:`with_all` or
    ``dataclasses.replace``. ``model["gx"]`` is the :class:`ChannelModel` of gx.
    """

    channels: Mapping[str, ChannelModel] = field(
        default_factory=lambda: {ch: ChannelModel() for ch in CHANNELS}
    )
    meta: Mapping[str, Any] = field(default_factory=dict)
    source: str = "<default>"

    def __post_init__(self) -> None:
        missing = [ch for ch in CHANNELS if ch not in self.channels]
        extra = [ch for ch in self.channels if ch not in CHANNELS]
        if missing or extra:
            raise ModelError(
                f"{self.source}: a NoiseModel needs exactly the channels {', '.join(CHANNELS)}"
                f" (missing {missing}, unknown {extra})"
            )

    def __getitem__(self, channel: str) -> ChannelModel:
        try:
            return self.channels[channel]
        except KeyError:
            raise ModelError(
                f"{self.source}: no channel {channel!r}; channels are {', '.join(CHANNELS)}"
            ) from None

    def check_nyquist(self, rate_hz: float, channels: Iterable[str] = CHANNELS) -> None:
        """Every resonance of ``channels`` lies below the Nyquist frequency of samples at
        ``rate_hz``; a ModelError naming the model file, the channel and the key."""
        nyquist = 0.5 * rate_hz
        for ch in channels:
            cm = self[ch]
            for key in ("resonance_freq_hz", "resonance_width_hz"):
                value = float(getattr(cm, key))
                if cm.resonance_height > 0 and not value < nyquist:
                    raise ModelError(
                        f"{self.source}: [channels.{ch}] {key} = {value:g} Hz must lie "
                        f"below the Nyquist frequency {nyquist:g} Hz of the {rate_hz:g} "
                        "Hz output")

    def with_channel(self, channel: str, **overrides: float) -> NoiseModel:
        """A copy where ``channel`` has some keys changed, e.g. ``with_channel("gx", white=0)``."""
        new = dict(self.channels)
        merged = {**self[channel].to_dict(), **overrides}
        new[channel] = _channel_from_table(merged, self.source, f"channels.{channel}", channel)
        return dataclasses.replace(self, channels=new)

    def with_all(self, **overrides: float) -> NoiseModel:
        """A copy with the same keys changed on every channel."""
        new = {
            ch: _channel_from_table(
                {**self[ch].to_dict(), **overrides}, self.source, f"channels.{ch}", ch
            )
            for ch in CHANNELS
        }
        return dataclasses.replace(self, channels=new)

    @classmethod
    def quiet(cls) -> NoiseModel:
        """No noise, no bias, no errors on any channel."""
        return cls(source="<quiet>")

    @classmethod
    def single_term(cls, channel: str, **terms: float) -> NoiseModel:
        """A quiet model with ``terms`` on one channel (handy in tests and studies)."""
        return cls.quiet().with_channel(channel, **terms)

    # ------------------------------------------------------------------ file I/O
    @classmethod
    def from_dict(
        cls, d: Mapping[str, Any], source: str = "<dict>", *, text: str | None = None
    ) -> NoiseModel:
        """Build a model from the parsed TOML structure.

        Args:
            d: ``{"meta": {...}, "defaults": {...}, "channels": {"gx": {...}, ...}}``.
            source: name used in error messages (the file path).
            text: the file text, used only to find line numbers for error messages.

        Raises:
            ModelError: unknown table or key, wrong type, negative magnitude.
        """
        loc = _Locator(source, text)
        if not isinstance(d, Mapping):
            raise ModelError(f"{source}: a noise model must be a table, got {type(d).__name__}")
        for top in d:
            if top not in ("meta", "defaults", "channels"):
                raise ModelError(
                    f"{loc.where(top, None)}: unknown table or key {top!r}; a noise model has"
                    " the tables [meta], [defaults] and [channels.<gx|gy|gz|ax|ay|az>]"
                )
        meta = d.get("meta", {})
        if not isinstance(meta, Mapping):
            raise ModelError(f"{loc.where('meta', None)}: 'meta' must be a table")
        defaults_tbl = d.get("defaults", {})
        if not isinstance(defaults_tbl, Mapping):
            raise ModelError(f"{loc.where('defaults', None)}: 'defaults' must be a table")
        channels_tbl = d.get("channels", {})
        if not isinstance(channels_tbl, Mapping):
            raise ModelError(f"{loc.where('channels', None)}: 'channels' must be a table")
        _check_table(defaults_tbl, loc, "defaults", channel=None)
        for ch, tbl in channels_tbl.items():
            if ch not in CHANNELS:
                raise ModelError(
                    f"{loc.where('channels.' + str(ch), None)}: unknown channel {ch!r} in"
                    f" [channels]; channels are {', '.join(CHANNELS)}"
                )
            if not isinstance(tbl, Mapping):
                raise ModelError(f"{loc.where('channels.' + ch, None)}: must be a table")
            _check_table(tbl, loc, f"channels.{ch}", channel=ch)
        for key, value in defaults_tbl.items():
            if (key.startswith("g_sensitivity_") or key.startswith("cross_")) and value:
                raise ModelError(
                    f"{loc.where('defaults', key)}: {key!r} is axis-specific and cannot go in"
                    " [defaults]; set it in the [channels.<ch>] tables"
                )
        chans: dict[str, ChannelModel] = {}
        for ch in CHANNELS:
            merged = {**defaults_tbl, **channels_tbl.get(ch, {})}
            values: dict[str, Any] = {k: _as_number(k, v) for k, v in merged.items()}
            chans[ch] = ChannelModel(**values)
            _check_merged(chans[ch], loc, f"channels.{ch}")
        return cls(channels=chans, meta=dict(meta), source=source)

    def to_dict(self) -> dict[str, Any]:
        """The file structure; only keys that differ from the built-in defaults are written."""
        base = ChannelModel()
        out: dict[str, Any] = {}
        if self.meta:
            out["meta"] = dict(self.meta)
        chans: dict[str, dict[str, float]] = {}
        for ch in CHANNELS:
            cm = self[ch]
            chans[ch] = {k: getattr(cm, k) for k in KEYS if getattr(cm, k) != getattr(base, k)}
        out["channels"] = chans
        return out

    def to_toml(self) -> str:
        """TOML text that :func:`load_model` reads back into an equal model, headed by a
        comment with the units of the keys (:data:`UNITS_HEADER`)."""
        return UNITS_HEADER + tomli_w.dumps(self.to_dict())


UNITS_HEADER = """\
# Noise model (docs/noise-model.md). u = dps for gx gy gz, g for ax ay az.
# white, output_white: u/sqrt(Hz); flicker, markov_sigma, sine_amplitude,
# outlier_amplitude, bias: u; random_walk: u/sqrt(s); ramp: u/s; quantization: u*s;
# markov_tau: s; sine_freq, resonance_freq_hz, resonance_width_hz, bandwidth_hz: Hz;
# resonance_height: u^2/Hz; outlier_rate: 1/s; temp_coeff: u/degC; temp_coeff2: u/degC^2;
# temp_ref: degC; scale_error, cross_x/y/z: fraction; scale_temp_coeff: 1/degC;
# scale_temp_coeff2: 1/degC^2; nonlinearity: 1/u; g_sensitivity_x/y/z: dps/g.

"""
"""Comment at the head of every model file :meth:`NoiseModel.to_toml` writes (a model
file read by a person had no units)."""


DATASHEET_PREFIX = "datasheet:"
"""A model named ``datasheet:CHIP`` (``load_model("datasheet:lsm6dsl")``, ``sim://...&model=
datasheet:lsm6dsl``, ``--model datasheet:lsm6dsl``) is the chip's shipped datasheet-typical
model, a data file of this package (``lsm6ds_sim/datasheet/CHIP.toml``, read through
:mod:`importlib.resources`, so an installed wheel has it too)."""


def datasheet_chips() -> tuple[str, ...]:
    """The chips with a shipped datasheet-typical model, sorted."""
    folder = resources.files(__package__) / "datasheet"
    return tuple(sorted(f.name[: -len(".toml")] for f in folder.iterdir()
                        if f.name.endswith(".toml")))


def datasheet_model_file(chip: str) -> Traversable:
    """The shipped datasheet-typical model file of ``chip`` (the one resolver every
    ``datasheet:CHIP`` name and the fit's datasheet comparison go through).

    Raises:
        ModelError: no model is shipped for ``chip`` (the message lists the chips).
    """
    name = chip.strip().lower()
    if name not in datasheet_chips():
        raise ModelError(f"{DATASHEET_PREFIX}{chip}: no datasheet model is shipped for "
                         f"{chip!r}; shipped: {', '.join(datasheet_chips())}")
    return resources.files(__package__) / "datasheet" / f"{name}.toml"


def load_model(path: str | Path) -> NoiseModel:
    """Read a noise model file (TOML), or the shipped model named ``datasheet:CHIP``.

    Raises:
        ModelError: the file is missing, is not valid TOML, or breaks a rule of the format
            (the message names the file, the table, the key and the line).
    """
    spec = str(path)
    source: Traversable
    if spec.startswith(DATASHEET_PREFIX):
        source = datasheet_model_file(spec[len(DATASHEET_PREFIX):])
    else:
        source = Path(path)
        spec = str(source)
    try:
        if isinstance(source, Path) and source.exists() and not source.is_file():
            raise ModelError(f"{spec}: not a regular file (a noise model is a TOML file)")
        text = source.read_text(encoding="utf-8")
    except OSError as exc:
        raise ModelError(f"{spec}: cannot read the noise model file ({exc.strerror})") from exc
    except ValueError as exc:  # not UTF-8 text, a NUL in the name
        raise ModelError(f"{spec}: cannot read the noise model file ({exc})") from exc
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ModelError(f"{spec}: not valid TOML: {exc}") from exc
    return NoiseModel.from_dict(data, source=spec, text=text)


# ---------------------------------------------------------------------- validation
class _Locator:
    """Finds the line of ``key`` inside ``[table]`` in the file text (best effort)."""

    _header = re.compile(r"^\s*\[\s*([A-Za-z0-9_.\" -]+?)\s*\]\s*(#.*)?$")

    def __init__(self, source: str, text: str | None) -> None:
        self.source = source
        self.text = text

    def line(self, table: str, key: str | None) -> int | None:
        if self.text is None:
            return None
        current = ""
        for i, raw in enumerate(self.text.splitlines(), start=1):
            m = self._header.match(raw)
            if m:
                current = m.group(1).replace('"', "").replace(" ", "")
                if key is None and (current == table or current.startswith(table + ".")):
                    return i
                continue
            if key is None:
                if current == "" and re.match(rf"^\s*{re.escape(table)}\s*[=.]", raw):
                    return i
                continue
            if current == table and re.match(rf"^\s*\"?{re.escape(key)}\"?\s*=", raw):
                return i
            # dotted keys under a parent table, e.g. [channels] gx.white = 1
            if table.startswith(current + ".") if current else True:
                rest = table[len(current) + 1 :] if current else table
                if re.match(rf"^\s*{re.escape(rest)}\s*\.\s*{re.escape(key)}\s*=", raw):
                    return i
        return None

    def where(self, table: str, key: str | None) -> str:
        line = self.line(table, key)
        at = f"{self.source}" + (f", line {line}" if line is not None else "")
        if key is None:
            return f"{at}, [{table}]"
        return f"{at}, [{table}] key {key!r}"


def _as_number(key: str, value: Any) -> float | int:
    if key in _INT_KEYS:
        return int(value)
    return float(value)


def _check_table(tbl: Mapping[str, Any], loc: _Locator, table: str, channel: str | None) -> None:
    for key, value in tbl.items():
        if key not in KEYS:
            hint = _closest(key)
            raise ModelError(
                f"{loc.where(table, key)}: unknown key {key!r}"
                + (f" (did you mean {hint!r}?)" if hint else "")
                + "; allowed keys are listed in docs/noise-model.md"
            )
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ModelError(
                f"{loc.where(table, key)}: must be a number, got {type(value).__name__} {value!r}"
            )
        if not math.isfinite(value):
            raise ModelError(f"{loc.where(table, key)}: must be finite, got {value!r}")
        if key in NON_NEGATIVE_KEYS and value < 0:
            raise ModelError(
                f"{loc.where(table, key)}: must be >= 0, got {value!r}"
                " (a magnitude, rate, time or frequency cannot be negative)"
            )
        if key == "filter_order" and value not in (1, 2):
            raise ModelError(f"{loc.where(table, key)}: must be 1 or 2, got {value!r}")
        if channel is not None:
            if key.startswith("g_sensitivity_") and value and channel not in GYRO_CHANNELS:
                raise ModelError(
                    f"{loc.where(table, key)}: g-sensitivity applies to gyro channels only"
                )
            if key == f"cross_{channel[1]}" and value:
                raise ModelError(
                    f"{loc.where(table, key)}: {key!r} couples {channel} into itself;"
                    " use scale_error for the own axis"
                )


def _check_merged(cm: ChannelModel, loc: _Locator, table: str) -> None:
    """Rules that involve two keys, checked after [defaults] and the channel are merged."""
    if cm.markov_sigma > 0 and cm.markov_tau == 0:
        raise ModelError(
            f"{loc.where(table, 'markov_sigma')}: markov_sigma > 0 needs markov_tau > 0 (s)"
        )
    if cm.sine_amplitude > 0 and cm.sine_freq == 0:
        raise ModelError(
            f"{loc.where(table, 'sine_amplitude')}: sine_amplitude > 0 needs sine_freq > 0"
            " (Hz); a constant offset is 'bias'"
        )
    _check_resonance(cm, loc, table)


RESONANCE_KEYS: tuple[str, ...] = ("resonance_freq_hz", "resonance_width_hz",
                                   "resonance_height")
"""The three keys of the resonance term: all > 0, or all 0 (no resonance)."""


def _check_resonance(cm: ChannelModel, loc: _Locator, table: str) -> None:
    """A resonance needs its centre, its width and its height, all > 0."""
    given = [k for k in RESONANCE_KEYS if getattr(cm, k) > 0]
    if given and len(given) < len(RESONANCE_KEYS):
        missing = [k for k in RESONANCE_KEYS if k not in given]
        raise ModelError(
            f"{loc.where(table, given[0])}: {', '.join(given)} > 0 needs "
            f"{' and '.join(missing)} > 0 too (a resonance is a centre in Hz, a -3 dB "
            "width in Hz and a peak PSD height in unit^2/Hz)"
        )


def _channel_from_table(
    tbl: Mapping[str, Any], source: str, table: str, channel: str | None = None
) -> ChannelModel:
    loc = _Locator(source, None)
    _check_table(tbl, loc, table, channel=channel)
    values: dict[str, Any] = {k: _as_number(k, v) for k, v in tbl.items()}
    cm = ChannelModel(**values)
    _check_merged(cm, loc, table)
    return cm


def _closest(key: str) -> str | None:
    import difflib

    hits = difflib.get_close_matches(key, KEYS, n=1, cutoff=0.6)
    return hits[0] if hits else None


__all__ = [
    "ACCEL_CHANNELS",
    "DATASHEET_PREFIX",
    "GYRO_CHANNELS",
    "KEYS",
    "NON_NEGATIVE_KEYS",
    "RESONANCE_KEYS",
    "ChannelModel",
    "NoiseModel",
    "datasheet_chips",
    "datasheet_model_file",
    "load_model",
]
