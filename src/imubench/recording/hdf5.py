"""HDF5 recordings (``.h5``, ``.hdf5``) through h5py, for large recordings and for tools
that read HDF5 (MATLAB, pandas, HDFView).

Layout (every sample dataset chunked by :data:`CHUNK_SAMPLES` samples, gzip-compressed
with the shuffle filter, resizable, and carrying a ``units`` attribute; every dataset has
a Fletcher-32 checksum per chunk, the file's object headers have theirs (``libver``
v110), and all text is fixed-length: a damaged file is refused, never read as other
numbers):

========================  ======== ===========================================
dataset                   type     content
========================  ======== ===========================================
``/index``                int64    sample index (ODR periods since the start)
``/t_s``                  float64  time since the start, s
``/gyro_dps``             float64  (n, 3): gx, gy, gz in dps (``columns`` attr)
``/accel_g``              float64  (n, 3): ax, ay, az in g
``/temp_c``               float32  die temperature, degC (NaN: not measured)
``/raw``                  int16    (n, 6) raw counts, when the source had them
``/gaps/at_index``        int64    gaps (written on close): the index after the hole
``/gaps/lost``            int64    samples lost in the hole
``/gaps/reason``          str      why (fixed-length UTF-8)
========================  ======== ===========================================

The root group's attributes are the recording's metadata (the native header's keys:
``odr_hz``, ``chip``, ``fs_dps``...; a key's unit is in its name); nested values are
JSON text, listed in the ``json_keys`` attribute. ``format`` is ``imubench-hdf5``,
``complete`` is set when the writer closed the file (an interrupted writer leaves it
false). Reading: :func:`read_hdf5` (the whole file; a damaged file is refused, naming
it: HDF5 cannot be read around damage the way ``.imbr`` records can).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from imubench.batch import CHANNELS, Batch, Gap, explain_holes
from imubench.errors import RecordingError
from imubench.recording.commit import need_parent

FORMAT = "imubench-hdf5"
VERSION = 1
CHUNK_SAMPLES = 65536
"""Samples per chunk: 1.5 MiB of values per gyro/accel chunk, a fraction of a second to
decompress; small enough that reading part of a recording reads little more."""
COMPRESSION_LEVEL = 1
"""gzip level. Measured on 3.0 M samples of a simulated LSM6DSL (30 min at 1660 Hz, raw
counts kept): level 1 writes 118 MB in 19 s, level 4 113 MB in 29 s (a loaded 2-core
machine): sensor noise in float64 barely compresses, so the faster level wins."""
_SERIES: dict[str, tuple[str, str, tuple[int, ...]]] = {
    # name: (dtype, units, shape after the sample axis)
    "index": ("int64", "samples (ODR periods since the start)", ()),
    "t_s": ("float64", "s", ()),
    "gyro_dps": ("float64", "dps", (3,)),
    "accel_g": ("float64", "g", (3,)),
    "temp_c": ("float32", "degC", ()),
}


def _set_attr(obj: Any, key: str, value: Any) -> bool:
    """Set attribute ``key``; True when the value was stored as JSON text. Text is stored
    as fixed-length UTF-8, inside the (checksummed) object header: variable-length text
    lives in HDF5's global heap, which has no checksum, and a damaged heap can make the
    HDF5 library loop while reading it."""
    import h5py

    as_json = not isinstance(value, bool | int | float | str)
    if isinstance(value, str) or as_json:
        data = (json.dumps(value, default=str) if as_json else value).encode()
        obj.attrs.create(key, data, dtype=h5py.string_dtype("utf-8", max(len(data), 1)))
    else:
        obj.attrs[key] = value
    return as_json


def _get_attr(value: Any) -> Any:
    if isinstance(value, bytes | np.bytes_):
        return bytes(value).decode("utf-8")
    return value.item() if isinstance(value, np.generic) else value


class Hdf5Writer:
    """Writes Batches to an HDF5 recording (module docstring); never overwrites."""

    def __init__(self, path: str | Path, metadata: dict[str, Any], **_: Any) -> None:
        import h5py

        self.path = Path(path)
        need_parent(self.path)
        self.metadata = dict(metadata)
        self.metadata.pop("storage", None)  # values are stored as float64, raw alongside
        self.samples = 0
        self.gaps = 0
        self.lost_samples = 0
        self._last_index: int | None = None
        try:
            # libver "v110": superblock v3 and v2 object headers, which carry checksums,
            # so damaged metadata is detected, not read (HDF5 >= 1.10 reads it)
            self._f: Any = h5py.File(self.path, "x", track_order=True,
                                     libver=("v110", "latest"))
        except FileExistsError:
            raise RecordingError(
                f"{self.path}: exists already; recordings are never overwritten") from None
        f = self._f
        json_keys = [key for key in sorted(self.metadata)
                     if _set_attr(f, key, self.metadata[key])]
        _set_attr(f, "json_keys", json_keys)
        _set_attr(f, "format", FORMAT)
        f.attrs["version"] = VERSION
        f.attrs["complete"] = False
        for name, (dtype, units, tail) in _SERIES.items():
            self._series(name, dtype, units, tail)
        _set_attr(f["gyro_dps"], "columns", "gx,gy,gz")
        _set_attr(f["accel_g"], "columns", "ax,ay,az")
        self._gaps: list[Gap] = []

    def _series(self, name: str, dtype: str, units: str, tail: tuple[int, ...]) -> None:
        ds = self._f.create_dataset(
            name, shape=(0, *tail), maxshape=(None, *tail), dtype=dtype,
            chunks=(CHUNK_SAMPLES, *tail), compression="gzip",
            compression_opts=COMPRESSION_LEVEL, shuffle=True, fletcher32=True)
        _set_attr(ds, "units", units)

    def write(self, batch: Batch) -> None:
        """Append a batch; its holes become gap entries with their declared reasons
        (:func:`~imubench.batch.explain_holes`)."""
        n = len(batch)
        if n and self._last_index is not None and int(batch.index[0]) <= self._last_index:
            raise RecordingError(f"{self.path}: sample index {int(batch.index[0])} does not "
                                 f"follow {self._last_index}")
        for gap in explain_holes(batch, self._last_index):
            self.write_gap(gap.at, gap.lost, gap.reason)
        if n == 0:
            return
        if batch.raw is not None and "raw" not in self._f:
            if self.samples:
                raise RecordingError(f"{self.path}: raw counts appeared mid-recording")
            self._series("raw", "int16", "LSB (raw counts)", (6,))
            _set_attr(self._f["raw"], "columns", ",".join(CHANNELS))
        parts: dict[str, np.ndarray] = {
            "index": batch.index, "t_s": batch.t_s, "gyro_dps": batch.values[:, :3],
            "accel_g": batch.values[:, 3:], "temp_c": batch.temp_c,
        }
        if "raw" in self._f:
            if batch.raw is None:
                raise RecordingError(f"{self.path}: a batch without raw counts")
            parts["raw"] = batch.raw
        for name, data in parts.items():
            ds = self._f[name]
            ds.resize(self.samples + n, axis=0)
            ds[self.samples:] = data
        self.samples += n
        self._last_index = int(batch.index[-1])

    def write_gap(self, at_index: int, lost: int, reason: str) -> None:
        """Record ``lost`` samples missing before ``at_index`` (written on close)."""
        self._gaps.append(Gap(at_index, lost, reason))
        self.gaps += 1
        self.lost_samples += lost

    def _write_gaps(self) -> None:
        """``/gaps``: fixed-width columns (the reasons as fixed-length UTF-8, so that every
        dataset can carry a checksum), known in full only at the end."""
        import h5py

        g = self._f.create_group("gaps")
        reasons = [gap.reason.encode() for gap in self._gaps]
        width = max((len(r) for r in reasons), default=1) or 1
        columns: dict[str, tuple[Any, Any, str | None]] = {
            "at_index": ([gap.at for gap in self._gaps], "int64",
                         "samples (index of the sample after the hole)"),
            "lost": ([gap.lost for gap in self._gaps], "int64", "samples"),
            "reason": (reasons, h5py.string_dtype("utf-8", width), None),
        }
        for name, (data, dtype, units) in columns.items():
            ds = g.create_dataset(name, data=np.asarray(data, dtype=dtype), dtype=dtype,
                                  maxshape=(None,), chunks=(1024,), fletcher32=True)
            if units:
                _set_attr(ds, "units", units)

    def close(self) -> None:
        if self._f is None:
            return
        try:
            self._write_gaps()
            self._f.attrs["complete"] = True
            self._f.attrs["samples"] = self.samples
            self._f.attrs["lost_samples"] = self.lost_samples
        finally:
            self._f.close()
            self._f = None

    def __enter__(self) -> Hdf5Writer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def read_hdf5(path: str | Path) -> tuple[dict[str, Any], Batch, list[Gap], bool]:
    """(metadata, samples, declared gaps, complete) of an HDF5 recording; RecordingError
    naming the file when it is not one or is damaged."""
    import h5py

    path = Path(path)
    try:
        with h5py.File(path, "r") as f:
            if _get_attr(f.attrs.get("format", b"")) != FORMAT:
                raise RecordingError(f"{path}: an HDF5 file but not an imubench recording "
                                     f"(no format={FORMAT!r} attribute); convert it first")
            json_keys = set(json.loads(_get_attr(f.attrs.get("json_keys", b"[]"))))
            meta: dict[str, Any] = {}
            for key, value in f.attrs.items():
                if key in ("json_keys", "format", "version", "complete", "samples",
                           "lost_samples"):
                    continue
                v = _get_attr(value)
                meta[key] = json.loads(v) if key in json_keys else v
            missing = [name for name in _SERIES if name not in f]
            if missing:
                raise RecordingError(
                    f"{path}: no dataset {', '.join('/' + m for m in missing)}: an "
                    f"imubench HDF5 recording has {', '.join('/' + n for n in _SERIES)}")
            for name, (_, units, _) in _SERIES.items():
                stated = _get_attr(f[name].attrs.get("units", units))
                if stated != units:  # a unit other than the name's is never read as it
                    raise RecordingError(
                        f"{path}: dataset /{name} states units {stated!r}; an imubench "
                        f"recording holds {units!r} there (convert the values first)")
            cols = {name: np.asarray(f[name][()]) for name in _SERIES}
            raw = np.asarray(f["raw"][()]) if "raw" in f else None
            complete = bool(f.attrs.get("complete", False))
            gaps = []
            if "gaps" in f:  # (written on close)
                g = f["gaps"]
                gaps = [Gap(int(a), int(n), _get_attr(r)) for a, n, r in
                        zip(g["at_index"][()], g["lost"][()], g["reason"][()], strict=True)]
    except RecordingError:
        raise
    except Exception as exc:  # h5py/HDF5: not HDF5, truncated, a damaged chunk or header
        raise RecordingError(f"{path}: cannot read the HDF5 file (damaged or not "
                             f"HDF5): {str(exc).splitlines()[0] if str(exc) else exc!r}"
                             ) from None
    n = len(cols["index"])
    shapes = {name: (n, *tail) for name, (_, _, tail) in _SERIES.items()}
    bad = [name for name, c in cols.items() if c.shape != shapes[name]]
    flipped = [name for name in bad if cols[name].shape == shapes[name][::-1]]
    if flipped:  # MATLAB writes column-major: a 3 x N dataset
        raise RecordingError(f"{path}: dataset /{flipped[0]} is {cols[flipped[0]].shape}, "
                             f"transposed: one row per sample, {shapes[flipped[0]]}, is "
                             "needed (MATLAB's h5write stores a matrix transposed)")
    if bad or (raw is not None and raw.shape != (n, len(CHANNELS))):
        raise RecordingError(f"{path}: dataset /{(bad or ['raw'])[0]} does not have one "
                             f"row per sample ({n}); damaged")
    if n > 1 and not np.all(np.diff(cols["index"]) > 0):
        raise RecordingError(f"{path}: /index does not increase (damaged)")
    if "odr_hz" not in meta:
        raise RecordingError(f"{path}: no odr_hz attribute; give --rate HZ")
    values = np.column_stack([cols["gyro_dps"], cols["accel_g"]]).astype(np.float64)
    batch = Batch(cols["index"].astype(np.int64), cols["t_s"].astype(np.float64), values,
                  cols["temp_c"].astype(np.float64),
                  None if raw is None else raw.astype(np.int16))
    return meta, batch, gaps, complete
