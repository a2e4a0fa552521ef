"""Up-front validation of a source URI (used by the configuration loader).

Catches at start-up what would otherwise fail minutes later: an unknown scheme, an
unknown chip, an ODR or full scale the chip does not have (with the allowed values).
"""

from __future__ import annotations

from lsm6ds.registers import CHIPS, accel_fs_code, chip_map, gyro_fs_code

from imubench.errors import SourceError
from imubench.sources.registry import SourceURI, available_schemes

CHIP_SCHEMES = {"sim", "i2c"}


def _chip_of(uri: SourceURI) -> str:
    chip = uri.target.strip("/").lower() if uri.scheme == "sim" else (uri.get_str("chip") or "")
    if uri.scheme == "sim" and not chip:
        chip = "lsm6dsl"
    chip = chip.lower()
    if chip not in CHIPS:
        what = "chip" if uri.scheme == "sim" else "parameter chip"
        raise SourceError(f"{what} {chip!r} is not supported; choose one of {', '.join(CHIPS)}")
    return chip


def check_source_uri(text: str) -> SourceURI:
    """Parse ``text`` and check what can be checked without opening the device."""
    uri = SourceURI.parse(text)
    schemes = available_schemes()
    if uri.scheme not in schemes:
        raise SourceError(f"unknown scheme {uri.scheme!r}; available: {', '.join(schemes)}")
    if uri.scheme in CHIP_SCHEMES:
        chip = chip_map(_chip_of(uri))
        odr = uri.get_float("odr_hz")
        if odr is not None:
            for sensor in ("accel", "gyro"):
                try:
                    chip.odr_code(odr, sensor)
                except ValueError as exc:
                    raise SourceError(f"odr_hz={odr:g}: {exc}") from None
        fs_dps = uri.get_float("fs_dps")
        fs_g = uri.get_float("fs_g")
        try:
            if fs_dps is not None:
                gyro_fs_code(fs_dps)
            if fs_g is not None:
                accel_fs_code(fs_g)
        except ValueError as exc:
            raise SourceError(str(exc)) from None
    return uri
