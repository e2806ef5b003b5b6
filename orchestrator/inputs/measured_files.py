"""Measured-data files: the CSV, HDF5 and MATLAB readers and the writer.

Sensor data (DESIGN §4.3) is a ``time`` column [s] and one column per sensor id.
The formats:

* **CSV** (``.csv``): one header row (``time,A1,A2,...``), lines starting with
  ``#`` are comments, delimiter ``,`` (``;`` and tab are recognised from the
  header). A column may declare its unit in the header: ``A1 [kPa]``.
* **HDF5** (``.h5``, ``.hdf5``): datasets ``time`` and one per sensor id, at
  the root or in a group ``sensors`` (``time`` may sit at the root while the
  channels are in ``sensors``); optional dataset attribute ``units``.
* **MATLAB** (``.mat``): variables ``time`` and one per sensor id, or one
  struct variable with those fields; optional struct variable ``units``
  (``units.A1 = 'kPa'``). v5/v7 files are read with :func:`scipy.io.loadmat`;
  v7.3 files are HDF5 and are read with h5py (same layout rules).

:func:`read_columns` returns what a file holds (:class:`RawColumns`: every numeric
vector by name, the declared units, the names skipped) without judging it; the checks
are :mod:`orchestrator.inputs.measured_checks`. :func:`write_measured` writes the same
three formats (for the synthetic measurement generator and the tests).
"""
from __future__ import annotations

import csv
import io
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

import numpy as np

from orchestrator.inputs.errors import UserInputError

__all__ = ["SUFFIXES", "RawColumns", "check_suffix", "read_columns", "write_measured"]

SUFFIXES = (".csv", ".h5", ".hdf5", ".mat")


@dataclass
class RawColumns:
    """What a format reader found: every numeric vector by name, declared units, skipped names."""

    columns: dict[str, np.ndarray]
    units: dict[str, str]
    skipped: list[str]


def check_suffix(path: Path) -> str:
    """The lower-case suffix of ``path`` when it is one of :data:`SUFFIXES`.

    Raises
    ------
    UserInputError
        Any other suffix (or none).
    """
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise UserInputError(f"{path}: unsupported measured-data format {path.suffix or '(no suffix)'!r}; "
                             f"supported: {', '.join(SUFFIXES)}")
    return suffix


def read_columns(path: Path, name: str) -> RawColumns:
    """Read the measured-data file ``path`` (named ``name`` in messages) by its suffix.

    Raises
    ------
    UserInputError
        Unsupported suffix, unreadable file, or a layout the format rules do not allow.
    """
    readers = {".csv": _read_csv, ".h5": _read_h5, ".hdf5": _read_h5, ".mat": _read_mat}
    return readers[check_suffix(path)](path, name)


# --------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------
def _read_csv(path: Path, name: str) -> RawColumns:
    """A CSV file -> its columns (header units in ``[...]``); fast path :func:`numpy.loadtxt`."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise UserInputError(f"{name}: cannot read as a text CSV file ({exc})") from None
    lines = text.splitlines()
    body = [(i + 1, ln) for i, ln in enumerate(lines) if ln.strip() and not ln.lstrip().startswith("#")]
    if not body:
        raise UserInputError(f"{name}: no header row (the file is empty or all comments)")
    header_no, header = body[0]
    delim = max((",", ";", "\t"), key=header.count)
    if header.count(delim) == 0:
        delim = ","
    names, units = [], {}
    for field in next(csv.reader([header], delimiter=delim)):
        m = re.fullmatch(r"\s*(.*?)\s*\[\s*([^\]]*?)\s*\]\s*", field)
        col = (m.group(1) if m else field.strip()).strip('"\' ')
        if m:
            units[col] = m.group(2)
        if col in names:
            raise UserInputError(f"{name}: line {header_no}: column {col!r} appears twice in the header")
        names.append(col)
    rows = body[1:]
    if not rows:
        raise UserInputError(f"{name}: a header (line {header_no}) but no data rows")
    ncol = len(names)
    try:
        data = np.loadtxt(io.StringIO("\n".join(ln for _, ln in rows)), delimiter=delim, comments="#",
                          dtype=float, ndmin=2)
        if data.size == 0:
            data = np.empty((0, ncol))
        if data.shape[1] != ncol:
            raise ValueError
    except ValueError:
        data = _parse_csv_rows(rows, names, delim, name)   # slow path: empty fields and exact error lines
    return RawColumns({c: data[:, j].copy() for j, c in enumerate(names)}, units, [])


def _parse_csv_rows(rows, names, delim, name) -> np.ndarray:
    """Row-by-row CSV parse: empty fields are NaN; errors name the line and the column."""
    out = np.empty((len(rows), len(names)))
    for r, (line_no, line) in enumerate(rows):
        fields = next(csv.reader([line.split("#", 1)[0]], delimiter=delim))
        if len(fields) != len(names):
            raise UserInputError(f"{name}: line {line_no}: {len(fields)} fields, the header has {len(names)}")
        for j, f in enumerate(fields):
            f = f.strip()
            try:
                out[r, j] = float(f) if f else math.nan
            except ValueError:
                raise UserInputError(f"{name}: line {line_no}: column {names[j]!r}: {f!r} is not a number") from None
    return out


def _read_h5(path: Path, name: str) -> RawColumns:
    """An HDF5 file -> its datasets (``time`` and the channels, see :func:`_read_h5_groups`)."""
    import h5py

    if not h5py.is_hdf5(path):
        raise UserInputError(f"{name}: not an HDF5 file")
    try:
        with h5py.File(path, "r") as f:
            return _read_h5_groups(f, name, matlab=False)
    except OSError as exc:
        raise UserInputError(f"{name}: cannot read HDF5 file ({exc})") from None


def _read_h5_groups(f, name: str, *, matlab: bool) -> RawColumns:
    """Find ``time`` and the channels in an open HDF5 file (plain or MATLAB v7.3)."""
    import h5py

    groups = [k for k, v in f.items() if isinstance(v, h5py.Group) and not k.startswith("#")]
    if "sensors" in groups:
        group = f["sensors"]
    elif "time" in f:
        group = f
    else:   # a MATLAB struct variable holding time and the channels
        group = next((f[k] for k in groups if "time" in f[k]), None)
        if group is None:
            raise UserInputError(f"{name}: no dataset 'time' at the root or in a group (found: "
                                 f"{', '.join(sorted(f.keys())) or 'nothing'})")
    raw = RawColumns({}, {}, [])
    members = dict(group.items())
    if group.name != "/":   # time (and a MATLAB units struct) may sit at the root beside the group
        for key in ("time", "units"):
            if key not in members and key in f:
                members[key] = f[key]
        raw.skipped += [k for k in f if k not in members and k != group.name.strip("/") and not k.startswith("#")]
    for key, obj in members.items():
        if key.startswith("#"):
            continue
        if isinstance(obj, h5py.Group):
            if matlab and key == "units":
                raw.units.update({k: _matlab_text(v) for k, v in obj.items() if isinstance(v, h5py.Dataset)})
            else:
                raw.skipped.append(key)
            continue
        if obj.dtype.kind not in "fiub" or _text(obj.attrs.get("MATLAB_class", "")) == "char":
            raw.skipped.append(key)
            continue
        raw.columns[key] = np.asarray(obj[()], dtype=float)
        unit = obj.attrs.get("units", obj.attrs.get("unit"))
        if unit is not None:
            raw.units[key] = _text(unit)
    return raw


def _text(value) -> str:
    """An HDF5 attribute value (str, bytes or a 1-element array of either) as str."""
    if isinstance(value, np.ndarray):
        value = value.ravel()[0] if value.size else ""
    return value.decode() if isinstance(value, bytes) else str(value)


def _matlab_text(ds) -> str:
    """A MATLAB v7.3 char array (uint16 code units) as str."""
    codes = np.asarray(ds[()]).ravel()
    return "".join(chr(int(c)) for c in codes) if codes.dtype.kind in "iu" else _text(codes)


def _read_mat(path: Path, name: str) -> RawColumns:
    """A MATLAB file -> its numeric variables (or a struct's fields) and the ``units`` struct.

    v7.3 files are HDF5 and go through :func:`_read_h5_groups`.
    """
    import scipy.io

    try:
        major, _ = scipy.io.matlab.matfile_version(str(path))
    except Exception as exc:   # scipy raises ValueError / MatReadError variants for non-MAT files
        raise UserInputError(f"{name}: not a MATLAB .mat file ({exc})") from None
    if major == 2:   # v7.3: HDF5 with a MATLAB user block
        import h5py
        try:
            with h5py.File(path, "r") as f:
                return _read_h5_groups(f, name, matlab=True)
        except OSError as exc:
            raise UserInputError(f"{name}: cannot read MATLAB v7.3 (HDF5) file ({exc})") from None
    try:
        variables = scipy.io.loadmat(str(path), simplify_cells=True)
    except Exception as exc:
        raise UserInputError(f"{name}: cannot read MATLAB file ({exc})") from None
    top = {k: v for k, v in variables.items() if not k.startswith("__")}
    if "time" not in top:
        structs = [k for k, v in top.items() if isinstance(v, dict) and "time" in v]
        if not structs:
            raise UserInputError(f"{name}: no variable 'time' and no struct with a field 'time' "
                                 f"(variables: {', '.join(sorted(top)) or 'none'})")
        outer = [k for k in top if k != structs[0]]
        top = dict(top[structs[0]])
        top.setdefault("units", variables.get("units"))
        skipped = [k for k in outer if k != "units"]
    else:
        skipped = []
    raw = RawColumns({}, {}, skipped)
    for key, value in top.items():
        if key == "units" and isinstance(value, dict):
            raw.units.update({k: str(v) for k, v in value.items()})
            continue
        if value is None:
            continue
        arr = np.asarray(value)
        if arr.dtype.kind not in "fiub":
            raw.skipped.append(key)
            continue
        raw.columns[key] = arr.astype(float)
    return raw


# --------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------
def write_measured(path: str | Path, data_t: np.ndarray, channels: Mapping[str, np.ndarray],
                   units: Mapping[str, str] | None = None) -> Path:
    """Write sensor data as CSV, HDF5 or MATLAB v5 ``.mat`` (by suffix).

    Layouts are those :func:`orchestrator.inputs.measured.read_measured` reads: CSV header
    ``time,A1 [unit],...`` (time with 17 significant digits so it round-trips exactly,
    channels with 12, more than any sensor resolves); HDF5 ``/time`` and ``/sensors/<id>``
    with a ``units`` attribute; MAT variables ``time``, ``<id>`` (column vectors) and the
    struct ``units``.

    Parameters
    ----------
    path : str or Path
        Output file; suffix one of :data:`SUFFIXES`.
    data_t : ndarray, shape (nt,)
        Times [s].
    channels : mapping of str to ndarray, shape (nt,)
        Signals by sensor id (NaN allowed).
    units : mapping of str to str, optional
        Unit per column (``"time"`` or an id), written into the file; ``None``
        writes no unit (SI implied).

    Returns
    -------
    Path
        ``path``.
    """
    path = Path(path)
    writers = {".csv": _write_csv, ".h5": _write_h5, ".hdf5": _write_h5, ".mat": _write_mat}
    write = writers[check_suffix(path)]
    t, cols = _as_float_columns(data_t, channels)
    write(path, t, cols, dict(units or {}))
    return path


def _as_float_columns(data_t, channels: Mapping[str, np.ndarray]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Times and channels as float arrays, shape (nt,) each.

    Raises
    ------
    ValueError
        A channel whose shape differs from the times', or one named ``time``.
    """
    t = np.asarray(data_t, dtype=float)
    cols = {k: np.asarray(v, dtype=float) for k, v in channels.items()}
    for k, v in cols.items():
        if k == "time" or v.shape != t.shape:
            raise ValueError(f"channel {k!r}: shape {v.shape} vs time {t.shape} (or the reserved name 'time')")
    return t, cols


def _write_csv(path: Path, t: np.ndarray, cols: dict[str, np.ndarray], units: dict[str, str]) -> None:
    """CSV: header ``time [unit],A1 [unit],...``; time with 17 significant digits, channels with 12."""
    head = ["time" + (f" [{units['time']}]" if "time" in units else "")]
    head += [k + (f" [{units[k]}]" if k in units else "") for k in cols]
    with open(path, "w", newline="") as fh:
        fh.write(",".join(head) + "\n")
        data = np.column_stack([t] + list(cols.values())) if cols else t[:, None]
        fmt = ["%.17g"] + ["%.12g"] * len(cols)
        np.savetxt(fh, data, delimiter=",", fmt=fmt)


def _write_h5(path: Path, t: np.ndarray, cols: dict[str, np.ndarray], units: dict[str, str]) -> None:
    """HDF5: ``/time`` (attribute ``units``, default ``s``) and ``/sensors/<id>`` (``units`` where given)."""
    import h5py

    with h5py.File(path, "w") as f:
        f["time"] = t
        f["time"].attrs["units"] = units.get("time", "s")
        g = f.create_group("sensors")
        for k, v in cols.items():
            g[k] = v
            if k in units:
                g[k].attrs["units"] = units[k]


def _write_mat(path: Path, t: np.ndarray, cols: dict[str, np.ndarray], units: dict[str, str]) -> None:
    """MATLAB v5: variables ``time`` and ``<id>`` (column vectors), struct ``units`` where given.

    Raises
    ------
    ValueError
        A sensor id that is not a MATLAB variable name, or is ``units``.
    """
    import scipy.io

    bad = [k for k in cols if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]{0,62}", k) or k == "units"]
    if bad:
        raise ValueError(f"sensor ids {bad} are not valid MATLAB variable names (or are 'units')")
    mdict = {"time": t, **cols}
    if units:
        mdict["units"] = dict(units)
    scipy.io.savemat(str(path), mdict, oned_as="column")
