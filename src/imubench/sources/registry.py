"""Source backends registered by URI scheme, each with its URI parameters declared once.

    SIM = Backend("sim", params=(Param("odr_hz", float, 104.0, "output data rate, Hz"), ...),
                  options=sim_options, build=build_sim)
    register_backend(SIM)

    source = open_source("sim://lsm6dsl?odr_hz=104&seed=1")

A backend is two functions over one parameter table: ``options(uri)`` checks the URI
against the table (unknown names, types, choices) and everything else that can be checked
without touching a device (chip, ODR, full scale, files), returning typed options;
``build(uri, options)`` makes the (not yet opened) source from them. The configuration
loader calls only ``options`` (:func:`check_source_uri`), :func:`open_source` calls both,
so validation and construction cannot disagree.

Backends live in their own modules; :data:`BUILTIN_MODULES` are imported lazily the
first time a scheme is looked up, so importing imubench stays cheap.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any
from urllib.parse import parse_qsl, quote, unquote, urlsplit

from imubench.errors import SourceError
from imubench.sources.base import Source

_REGISTRY: dict[str, Backend] = {}

BUILTIN_MODULES: tuple[str, ...] = (
    "imubench.sources.replay",
    "imubench.sources.chip",
    "imubench.sources.sensortile",
)

_BOOL_TEXT = {"1": True, "true": True, "yes": True, "on": True,
              "0": False, "false": False, "no": False, "off": False}


@dataclass(frozen=True)
class Param:
    """One URI query parameter of a backend.

    Attributes:
        name: the parameter name in the URI.
        kind: ``int`` (decimal or 0x hex), ``float``, ``bool`` (1/0/true/false/yes/no/on/
            off) or ``str``.
        default: value when absent (None: absent means "not set").
        doc: one line for the documentation and error messages, with the unit.
        choices: allowed values of a ``str`` parameter.
    """

    name: str
    kind: type
    default: Any
    doc: str
    choices: tuple[str, ...] | None = None

    def parse(self, uri_text: str, raw: str) -> Any:
        try:
            if self.kind is bool:
                return _BOOL_TEXT[raw.lower()]
            if self.kind is int:
                return int(raw, 0)
            if self.kind is float:
                value = float(raw)
                if value != value or value in (float("inf"), float("-inf")):
                    raise ValueError(raw)
                return value
        except (ValueError, KeyError):
            what = {bool: "a boolean (1/0/true/false)", int: "an integer",
                    float: "a finite number"}[self.kind]
            raise SourceError(
                f"source URI {uri_text!r}: parameter {self.name}={raw!r} is not {what} "
                f"({self.doc})"
            ) from None
        if self.choices is not None and raw not in self.choices:
            raise SourceError(
                f"source URI {uri_text!r}: parameter {self.name}={raw!r} must be one of "
                f"{', '.join(self.choices)}"
            )
        return raw


@dataclass(frozen=True)
class SourceURI:
    """A parsed source URI: ``scheme://netloc/path?key=value&...``.

    ``target`` is netloc + path with percent-escapes decoded (``sim://lsm6dsl`` ->
    ``lsm6dsl``; ``i2c:///dev/i2c-1`` -> ``/dev/i2c-1``; ``replay://rec.imbr`` ->
    ``rec.imbr``).
    """

    text: str
    scheme: str
    target: str
    params: dict[str, str]

    @classmethod
    def parse(cls, text: str) -> SourceURI:
        parts = urlsplit(text)
        if not parts.scheme:
            raise SourceError(f"source URI {text!r} has no scheme (e.g. sim://lsm6dsl)")
        params: dict[str, str] = {}
        for key, value in parse_qsl(parts.query, keep_blank_values=True):
            if key in params:
                raise SourceError(f"source URI {text!r}: parameter {key!r} given twice")
            params[key] = value
        return cls(text, parts.scheme.lower(), unquote(parts.netloc + parts.path), params)

    def values(self, params: tuple[Param, ...]) -> dict[str, Any]:
        """Every declared parameter, typed (defaults where absent); unknown names refused
        with the accepted ones (typos must not pass)."""
        known = {p.name: p for p in params}
        unknown = sorted(set(self.params) - set(known))
        if unknown:
            raise SourceError(
                f"source URI {self.text!r}: unknown parameter(s) {', '.join(unknown)}; "
                f"{self.scheme}:// accepts {', '.join(sorted(known))}"
            )
        return {
            name: p.parse(self.text, self.params[name]) if name in self.params else p.default
            for name, p in known.items()
        }


@dataclass(frozen=True)
class Backend:
    """A source backend: its scheme, its URI parameters, and the two functions over them
    (see the module docstring)."""

    scheme: str
    params: tuple[Param, ...]
    options: Callable[[SourceURI], Any]
    build: Callable[[SourceURI, Any], Source]
    doc: str = ""

    def has_param(self, name: str) -> bool:
        return any(p.name == name for p in self.params)


def check_model_param(uri: SourceURI, model: str | None, rate_hz: float | None = None
                      ) -> None:
    """A simulator's ``model=`` (a noise model file or ``datasheet:CHIP``) loads, and its
    resonances lie below the Nyquist frequency of ``rate_hz`` (the rate the simulator
    generates at, when the URI fixes it); a SourceError naming the URI and the model
    (with the file, channel and key) otherwise."""
    if not model:
        return
    from lsm6ds_sim.model import load_model

    try:
        loaded = load_model(model)
        if rate_hz is not None:
            loaded.check_nyquist(rate_hz)
    except Exception as exc:  # ModelError and file errors, reported with the URI
        raise SourceError(f"source URI {uri.text!r}: model {model!r}: {exc}") from None


def register_backend(backend: Backend) -> Backend:
    _REGISTRY[backend.scheme.lower()] = backend
    return backend


def _load_builtins() -> None:
    for name in BUILTIN_MODULES:
        importlib.import_module(name)


def available_schemes() -> list[str]:
    _load_builtins()
    return sorted(_REGISTRY)


def backend_for(uri: SourceURI) -> Backend:
    """The backend of ``uri``'s scheme; SourceError naming the available ones."""
    if uri.scheme not in _REGISTRY:
        _load_builtins()
    backend = _REGISTRY.get(uri.scheme)
    if backend is None:
        raise SourceError(
            f"unknown source scheme {uri.scheme!r} in {uri.text!r}; available: "
            f"{', '.join(available_schemes())}"
        )
    return backend


def check_source_uri(text: str) -> SourceURI:
    """Parse ``text`` and check everything that can be checked without a device: scheme,
    parameter names, types and choices, chip, ODR, full scales, files."""
    uri = SourceURI.parse(text)
    backend_for(uri).options(uri)
    return uri


def with_default_param(uri: str, name: str, value: float) -> str:
    """``uri`` with ``name=value`` added when its backend declares that parameter and the
    URI does not set it; otherwise ``uri`` unchanged."""
    parsed = SourceURI.parse(uri)
    if name in parsed.params or not backend_for(parsed).has_param(name):
        return uri
    text = quote(f"{value:g}", safe="")  # 1e+06: a bare '+' would read as a space
    return uri + ("&" if "?" in uri else "?") + f"{name}={text}"


def open_source(uri: str) -> Source:
    """Create (not yet open) the source for ``uri``."""
    parsed = SourceURI.parse(uri)
    backend = backend_for(parsed)
    return backend.build(parsed, backend.options(parsed))
