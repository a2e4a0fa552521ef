"""Source backends registered by URI scheme.

    @register_source("sim")
    def _open_sim(uri: SourceURI) -> Source: ...

    source = open_source("sim://lsm6dsl?odr_hz=104&seed=1")

Backends live in their own modules; :data:`BUILTIN_MODULES` are imported lazily the
first time a scheme is looked up, so importing imubench stays cheap and a backend whose
optional dependency is missing fails only when it is used.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from urllib.parse import parse_qsl, unquote, urlsplit

from imubench.errors import SourceError
from imubench.sources.base import Source

SourceFactory = Callable[["SourceURI"], Source]
_REGISTRY: dict[str, SourceFactory] = {}

BUILTIN_MODULES: tuple[str, ...] = (
    "imubench.sources.replay",
    "imubench.sources.chip",
    "imubench.sources.sensortile",
)


@dataclass(frozen=True)
class SourceURI:
    """A parsed source URI: ``scheme://netloc/path?key=value&...``.

    ``target`` is netloc + path with percent-escapes decoded (``sim://lsm6dsl`` ->
    ``lsm6dsl``; ``i2c:///dev/i2c-1`` -> ``/dev/i2c-1``; ``replay://rec.imbr`` ->
    ``rec.imbr``). Typed getters raise :class:`SourceError` naming the parameter.
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

    def _get(self, name: str, kind: type, default: object, allowed: str) -> object:
        if name not in self.params:
            return default
        raw = self.params[name]
        try:
            if kind is bool:
                low = raw.lower()
                if low not in {"1", "0", "true", "false", "yes", "no", "on", "off"}:
                    raise ValueError(raw)
                return low in {"1", "true", "yes", "on"}
            return kind(raw, 0) if kind is int else kind(raw)
        except ValueError:
            raise SourceError(
                f"source URI {self.text!r}: parameter {name}={raw!r} is not {allowed}"
            ) from None

    def get_str(self, name: str, default: str | None = None) -> str | None:
        return self.params.get(name, default)

    def get_float(self, name: str, default: float | None = None) -> float | None:
        return self._get(name, float, default, "a number")  # type: ignore[return-value]

    def get_int(self, name: str, default: int | None = None) -> int | None:
        return self._get(name, int, default, "an integer")  # type: ignore[return-value]

    def get_bool(self, name: str, default: bool = False) -> bool:
        return self._get(name, bool, default, "a boolean (1/0/true/false)")  # type: ignore[return-value]

    def get_choice(self, name: str, choices: tuple[str, ...], default: str) -> str:
        value = self.params.get(name, default)
        if value not in choices:
            raise SourceError(
                f"source URI {self.text!r}: parameter {name}={value!r} must be one of "
                f"{', '.join(choices)}"
            )
        return value

    def check_known(self, known: set[str]) -> None:
        """Reject parameters the backend does not understand (typos must not pass)."""
        unknown = sorted(set(self.params) - known)
        if unknown:
            raise SourceError(
                f"source URI {self.text!r}: unknown parameter(s) {', '.join(unknown)}; "
                f"{self.scheme}:// accepts {', '.join(sorted(known))}"
            )


def register_source(scheme: str) -> Callable[[SourceFactory], SourceFactory]:
    """Class/function decorator registering a factory for ``scheme://`` URIs."""

    def deco(factory: SourceFactory) -> SourceFactory:
        _REGISTRY[scheme.lower()] = factory
        return factory

    return deco


def _load_builtins() -> None:
    for name in BUILTIN_MODULES:
        try:
            importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name != name:  # a real missing dependency inside the backend
                raise


def available_schemes() -> list[str]:
    _load_builtins()
    return sorted(_REGISTRY)


def open_source(uri: str) -> Source:
    """Create (not yet open) the source for ``uri``."""
    parsed = SourceURI.parse(uri)
    if parsed.scheme not in _REGISTRY:
        _load_builtins()
    factory = _REGISTRY.get(parsed.scheme)
    if factory is None:
        raise SourceError(
            f"unknown source scheme {parsed.scheme!r} in {uri!r}; available: "
            f"{', '.join(available_schemes())}"
        )
    return factory(parsed)
