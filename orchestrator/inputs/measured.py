"""Measured sensor data: read, check, align with a simulation, write.

Sensor data, simulated and measured alike (DESIGN §4.3), is a ``time`` column
[s] and one column per sensor id in SI units: ``pressure`` [Pa],
``displacement`` [m], ``acceleration`` [m/s²], ``strain`` [-]. Measured files
come as

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

:func:`read_measured` returns a :class:`MeasuredData` or raises
:class:`~orchestrator.inputs.errors.UserInputError` with one line naming the file, the
channel and the offending value or index. The checks, in order, and why:

1. **Channels.** Columns that are not sensors of the layout are ignored (noted).
   A ``required`` sensor that is absent is an error listing every missing id
   with close matches (:mod:`difflib`); an absent sensor that is not required
   is dropped (noted). A file with no sensor of the layout at all is an error.
2. **Time.** At least :data:`MIN_SAMPLES` samples; no NaN; strictly increasing
   (the first decreasing or repeated time is named with its index and both
   times); uniform: ``max |dt_i - median(dt)| <= UNIFORM_TOL * median(dt)``.
   Uniform sampling is what the cross-correlation alignment, the FFT-based
   filters (acceleration -> displacement reconstruction) and the RMSE per
   sample assume; 1 % tolerates time stamps rounded to 1 % of the step (so
   write times with enough digits: 8 significant digits at t = 10 s and
   2 kHz) and catches dropped samples (a missing sample is a 100 % jump) and
   a clock that jumps. HDF5/MAT channels whose length differs from
   ``time`` (a channel recorded at another rate) are an error naming both
   lengths and the implied rates.
3. **Gaps.** ±inf is an error (a conversion fault, not a dropout). NaN marks a
   dropout. A channel more than :data:`MAX_NAN_FRACTION` (20 %) NaN is an
   error: its RMSE would rest on a different, shorter passage than the other
   channels' and such a channel is a failing sensor, not a dropout. Runs of
   NaN no longer than ``max_gap`` seconds (a run of k missing samples lasts
   ``k*dt``; default :data:`MAX_GAP_SAMPLES` = 5 samples, i.e. 5 ms at 1 kHz,
   the length of telemetry packet losses, well below the ~20-40 ms a wheel
   needs to pass a sleeper at 120 km/h) are masked (``mask`` False, value NaN,
   noted with their times); a longer gap is an error, because it can hide a
   whole wheel passage or the impact peak the diagnosis relies on.
4. **Units.** A declared unit (CSV header, HDF5 ``units`` attribute, MAT
   ``units`` struct or the ``units`` argument) is converted to SI with the
   factors in :data:`UNIT_FACTORS` (noted); an unknown unit is an error. Then
   each type's peak magnitude ``max |x|`` is checked against physical bounds
   (:data:`PLAUSIBLE_PEAK`); outside them the data is almost surely in another
   unit and the error says which one is likely:

   ============  ==========================  ===================================
   type          implausible in SI when      reasoning
   ============  ==========================  ===================================
   pressure      max over all pressure       under a passing wheel a sleeper
                 channels < 500 Pa, or a     presses the ballast at 10 kPa-
                 channel > 50 MPa            2 MPa; so < 500 means kPa or
                                             MPa. The lower bound
                                             uses the largest pressure channel,
                                             because one cell under a void
                                             sleeper may rightly read ~0.
                                             > 50 MPa exceeds the strength of
                                             sleeper concrete and ballast.
   displacement  a channel > 0.05 m          rail and sleeper deflections are
                                             0.5-3 mm, with voids < ~10 mm; a
                                             peak of "1.5" is 1.5 mm.
   strain        a channel > 0.01            rail steel yields at ~2.5e-3,
                                             concrete crushes at ~3.5e-3; a
                                             peak of "150" is 150 µε.
   acceleration  a channel > 2e4 m/s²        ~2000 g, above the range of the
                                             accelerometers used on crossings
                                             (impacts reach some hundred g);
                                             such a peak means mm/s². g versus
                                             m/s² cannot be told from the
                                             magnitude: declare the unit.
   ============  ==========================  ===================================

:func:`check_rate` rejects data sampled below a required rate.

:func:`align` finds the time shift between a measured and a simulated passage
(normalised multichannel cross-correlation, parabolic sub-sample peak) and
:func:`resample` puts a simulation on the measured time base.
:func:`write_measured` writes the same three formats (for the synthetic
measurement generator and the tests).
"""
from __future__ import annotations

import csv
import io
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from track.sensors import SENSOR_TYPES   # the one list of sensor types (DESIGN §4.3)

from orchestrator.inputs.errors import UserInputError, did_you_mean as _hint

__all__ = [
    "SENSOR_TYPES",
    "SUFFIXES",
    "UNIT_FACTORS",
    "PLAUSIBLE_PEAK",
    "MIN_SAMPLES",
    "UNIFORM_TOL",
    "MAX_NAN_FRACTION",
    "MAX_GAP_SAMPLES",
    "MeasuredData",
    "read_measured",
    "check_measured",
    "check_rate",
    "align",
    "resample",
    "write_measured",
]

SUFFIXES = (".csv", ".h5", ".hdf5", ".mat")

MIN_SAMPLES = 3            # a step and a check of its uniformity need at least two intervals
UNIFORM_TOL = 0.01         # max |dt_i - median dt| / median dt (see module docstring, check 2)
MAX_NAN_FRACTION = 0.20    # a channel with more NaN is a failing sensor (check 3)
MAX_GAP_SAMPLES = 5        # default max_gap in samples (check 3)

_G_STANDARD = 9.80665      # m/s², the definition of the unit "g" (not a physical constant of the model)

# SI factor per declared unit, per quantity. Unit strings are compared after
# _normalise_unit (µ/μ -> u, ² -> 2, no blanks, no '^'), first exactly, then
# ignoring case.
UNIT_FACTORS: dict[str, dict[str, float]] = {
    "time": {"s": 1.0, "ms": 1e-3},
    "pressure": {"Pa": 1.0, "N/m2": 1.0, "kPa": 1e3, "kN/m2": 1e3, "MPa": 1e6, "N/mm2": 1e6,
                 "bar": 1e5, "mbar": 1e2, "psi": 6894.757293168},
    "displacement": {"m": 1.0, "cm": 1e-2, "mm": 1e-3, "um": 1e-6},
    "acceleration": {"m/s2": 1.0, "mm/s2": 1e-3, "g": _G_STANDARD, "gn": _G_STANDARD},
    "strain": {"-": 1.0, "": 1.0, "1": 1.0, "m/m": 1.0, "mm/m": 1e-3, "%": 1e-2, "ue": 1e-6, "uε": 1e-6,
               "um/m": 1e-6, "ustrain": 1e-6, "microstrain": 1e-6},
}

# (lower, upper, unit likely when below, unit likely when above) of the peak
# magnitude in SI; the lower bound applies to the largest channel of the type,
# the upper bound to every channel. Reasoning in the module docstring.
PLAUSIBLE_PEAK: dict[str, tuple[float | None, float | None, str, str]] = {
    "pressure": (500.0, 5e7, "kPa or MPa", "not Pa"),
    "displacement": (None, 0.05, "", "mm"),
    "strain": (None, 0.01, "", "µε"),
    "acceleration": (None, 2e4, "", "mm/s²"),
}

_PEAK_REASON = {
    "pressure": "ballast pressure under a loaded sleeper is 10 kPa-2 MPa",
    "displacement": "rail and sleeper deflections are millimetres",
    "strain": "rail and sleeper strains stay below ~3e-3",
    "acceleration": "accelerometers on crossings read at most some hundred g",
}


@dataclass(frozen=True)
class MeasuredData:
    """Checked sensor data on a uniform time base, SI units.

    Attributes
    ----------
    t : ndarray, shape (nt,)
        Sample times [s], strictly increasing and uniform.
    channels : dict of str to ndarray, shape (nt,)
        One signal per sensor id, SI units ([Pa], [m], [m/s²], [-]); NaN where
        masked.
    mask : dict of str to ndarray of bool, shape (nt,)
        True where the sample is valid, False where masked (a short NaN gap).
    source : str
        Where the data came from (the file name as given).
    notes : tuple of str
        One line per thing masked, dropped, ignored or converted.
    """

    t: np.ndarray
    channels: dict[str, np.ndarray]
    mask: dict[str, np.ndarray]
    source: str = "<arrays>"
    notes: tuple[str, ...] = ()

    @property
    def dt(self) -> float:
        """Sampling interval [s] (mean step over the record; uniform within 1 %)."""
        return float((self.t[-1] - self.t[0]) / (len(self.t) - 1))

    @property
    def rate(self) -> float:
        """Sampling rate [Hz]."""
        return 1.0 / self.dt


# --------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------
@dataclass
class _Raw:
    """What a format reader found: every numeric vector by name, declared units, skipped names."""

    columns: dict[str, np.ndarray]
    units: dict[str, str]
    skipped: list[str]


def read_measured(path: str | Path, sensors: Mapping[str, str], *, required: Sequence[str] | None = None,
                  max_gap: float | None = None, units: Mapping[str, str] | None = None) -> MeasuredData:
    """Read and check a measured sensor file (CSV, HDF5 or MATLAB ``.mat``).

    Parameters
    ----------
    path : str or Path
        The file; its suffix selects the format (:data:`SUFFIXES`).
    sensors : mapping of str to str
        Sensor id -> type (one of :data:`SENSOR_TYPES`), e.g. from the sensor
        layout YAML.
    required : sequence of str, optional
        Sensor ids that must be in the file. Default: none (but at least one
        sensor of ``sensors`` must be).
    max_gap : float, optional
        Longest NaN gap [s] that is masked rather than rejected; a gap of k
        missing samples lasts ``k*dt``. Default ``MAX_GAP_SAMPLES * dt``.
    units : mapping of str to str, optional
        Declared units by column name (``"time"`` or a sensor id); they take
        precedence over the units declared in the file.

    Returns
    -------
    MeasuredData

    Raises
    ------
    UserInputError
        For every problem listed in the module docstring; the message is one
        line naming the file, the channel and the offending value or index.
    """
    path = Path(path)
    name = str(path)
    suffix = path.suffix.lower()
    readers = {".csv": _read_csv, ".h5": _read_h5, ".hdf5": _read_h5, ".mat": _read_mat}
    if suffix not in readers:
        raise UserInputError(f"{name}: unsupported measured-data format {path.suffix or '(no suffix)'!r}; "
                             f"supported: {', '.join(SUFFIXES)}")
    _check_layout(sensors, name)
    if not path.is_file():
        raise UserInputError(f"{name}: measured-data file not found")
    raw = readers[suffix](path, name)
    declared = {**raw.units, **dict(units or {})}
    return check_measured(raw.columns, sensors, source=name, required=required, max_gap=max_gap,
                          units=declared, ignored=raw.skipped)


def _read_csv(path: Path, name: str) -> _Raw:
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
    return _Raw({c: data[:, j].copy() for j, c in enumerate(names)}, units, [])


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


def _read_h5(path: Path, name: str) -> _Raw:
    import h5py

    if not h5py.is_hdf5(path):
        raise UserInputError(f"{name}: not an HDF5 file")
    try:
        with h5py.File(path, "r") as f:
            return _read_h5_groups(f, name, matlab=False)
    except OSError as exc:
        raise UserInputError(f"{name}: cannot read HDF5 file ({exc})") from None


def _read_h5_groups(f, name: str, *, matlab: bool) -> _Raw:
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
    raw = _Raw({}, {}, [])
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


def _read_mat(path: Path, name: str) -> _Raw:
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
    raw = _Raw({}, {}, skipped)
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
# Checks
# --------------------------------------------------------------------------------------
def check_measured(columns: Mapping[str, np.ndarray], sensors: Mapping[str, str], *, source: str = "<arrays>",
                   required: Sequence[str] | None = None, max_gap: float | None = None,
                   units: Mapping[str, str] | None = None, ignored: Sequence[str] = ()) -> MeasuredData:
    """Check columns already in memory and build a :class:`MeasuredData`.

    The checks of :func:`read_measured` (which calls this after reading),
    usable on signals that never were a file (e.g. a synthetic measurement).
    The caller's arrays are not modified.

    Parameters
    ----------
    columns : mapping of str to array_like, shape (n,)
        ``"time"`` [s] and signals by name; names not in ``sensors`` are ignored.
    sensors, required, max_gap, units
        As in :func:`read_measured`.
    source : str
        Name used in messages and kept in the result.
    ignored : sequence of str
        Names the reader already skipped (non-numeric variables, groups); noted.

    Returns
    -------
    MeasuredData
    """
    name = source
    _check_layout(sensors, name)
    units = dict(units or {})
    notes: list[str] = []

    # 1. channels
    found = [c for c in columns if c != "time"]
    unknown = [c for c in found if c not in sensors] + list(ignored)
    if "time" not in columns:
        raise UserInputError(f"{name}: no 'time' column{_hint('time', found)} "
                             f"(columns: {', '.join(found) or 'none'})")
    missing_required = [s for s in (required or ()) if s not in columns]
    unknown_required = [s for s in (required or ()) if s not in sensors]
    if unknown_required:
        raise UserInputError(f"{name}: required sensor(s) {', '.join(map(repr, unknown_required))} "
                             f"are not in the sensor layout")
    if missing_required:
        listed = ", ".join(f"{s!r}{_hint(s, unknown)}" for s in missing_required)
        raise UserInputError(f"{name}: required sensor channel(s) missing: {listed}")
    present = [s for s in sensors if s in columns]
    if not present:
        raise UserInputError(f"{name}: none of the sensors {', '.join(map(repr, sensors))} is in the file "
                             f"(columns: {', '.join(found) or 'none'})")
    if unknown:
        notes.append(f"ignored columns that are not sensors of the layout: {', '.join(unknown)}")
    absent = [s for s in sensors if s not in columns]
    if absent:
        notes.append(f"sensors of the layout not in the file, dropped: {', '.join(absent)}")

    # 2. time
    t = _as_vector(columns["time"], name, "time")
    t_factor, note = _unit_factor(units.get("time"), "time", "time", name)
    if note:
        notes.append(note)
        t = t * t_factor
    _check_time(t, name)
    dt = float((t[-1] - t[0]) / (len(t) - 1))
    gap_limit = MAX_GAP_SAMPLES * dt if max_gap is None else float(max_gap)
    if not gap_limit >= 0.0:
        raise UserInputError(f"{name}: max_gap must be >= 0 s, got {max_gap!r}")

    channels, mask = {}, {}
    for sid in present:
        x = _as_vector(columns[sid], name, sid)
        if len(x) != len(t):
            span = t[-1] - t[0]
            raise UserInputError(
                f"{name}: channel {sid!r} has {len(x)} samples but time has {len(t)} (implied rates "
                f"{(len(x) - 1) / span:.6g} Hz vs {(len(t) - 1) / span:.6g} Hz): resample it onto the time base")
        factor, note = _unit_factor(units.get(sid), sensors[sid], sid, name)
        if note:
            notes.append(note)
        x = x * factor   # a new array: the caller's is left alone
        # 3. gaps
        bad = np.isinf(x)
        if bad.any():
            i = int(np.argmax(bad))
            raise UserInputError(f"{name}: channel {sid!r}: non-finite value {x[i]} at index {i} (t = {t[i]:.6g} s)")
        nan = np.isnan(x)
        if nan.any():
            frac = nan.mean()
            if frac > MAX_NAN_FRACTION:
                raise UserInputError(f"{name}: channel {sid!r} is {100 * frac:.1f} % NaN (more than "
                                     f"{100 * MAX_NAN_FRACTION:.0f} %): a failing sensor; remove it from the "
                                     f"layout or the file")
            runs = _nan_runs(nan)
            lengths = runs[:, 1] - runs[:, 0]
            worst = int(np.argmax(lengths))
            if lengths[worst] * dt > gap_limit * (1 + 1e-9):   # 1e-9: k*dt computed vs given in the same float
                i0, i1 = runs[worst]
                raise UserInputError(
                    f"{name}: channel {sid!r}: NaN gap of {lengths[worst]} samples ({lengths[worst] * dt:.6g} s) "
                    f"from index {i0} (t = {t[i0]:.6g} s) exceeds max_gap = {gap_limit:.6g} s")
            notes.append(f"{sid}: masked {int(nan.sum())} NaN samples in {len(runs)} gap(s) of at most "
                         f"{int(lengths.max())} samples, first at t = {t[runs[0, 0]]:.6g} s")
        channels[sid], mask[sid] = x, ~nan

    # 4. plausibility of the SI magnitudes
    _check_magnitudes(channels, sensors, units, name)
    return MeasuredData(t=t, channels=channels, mask=mask, source=name, notes=tuple(notes))


def _check_layout(sensors: Mapping[str, str], name: str) -> None:
    for sid, typ in sensors.items():
        if typ not in SENSOR_TYPES:
            raise UserInputError(f"{name}: sensor {sid!r} has type {typ!r}{_hint(str(typ), SENSOR_TYPES)}; "
                                 f"expected one of {', '.join(SENSOR_TYPES)}")
        if sid == "time":
            raise UserInputError(f"{name}: 'time' cannot be a sensor id")


def _as_vector(values, name: str, col: str) -> np.ndarray:
    arr = np.asarray(values, dtype=float)
    if arr.ndim != 1:
        squeezed = np.squeeze(arr)
        if squeezed.ndim != 1:
            raise UserInputError(f"{name}: {col!r} has shape {arr.shape}, expected a vector")
        arr = squeezed
    return arr


def _normalise_unit(unit: str) -> str:
    u = unit.strip().replace("µ", "u").replace("μ", "u").replace("²", "2").replace("^", "").replace(" ", "")
    return u


def _unit_factor(unit: str | None, quantity: str, col: str, name: str) -> tuple[float, str]:
    """SI factor of a declared unit and the note to record (empty when no conversion)."""
    if unit is None:
        return 1.0, ""
    table = UNIT_FACTORS[quantity]
    u = _normalise_unit(unit)
    factor = table.get(u)
    if factor is None:
        lowered = {k.lower(): v for k, v in table.items()}
        factor = lowered.get(u.lower())
    if factor is None:
        raise UserInputError(f"{name}: channel {col!r} ({quantity}): unknown unit {unit!r}; known: "
                             f"{', '.join(repr(k) for k in table)}")
    if factor == 1.0:
        return 1.0, ""
    return factor, f"{col}: converted from {unit} to SI (x {factor:g})"


def _check_time(t: np.ndarray, name: str) -> None:
    if len(t) < MIN_SAMPLES:
        raise UserInputError(f"{name}: time has {len(t)} samples, at least {MIN_SAMPLES} are needed")
    if np.isnan(t).any() or np.isinf(t).any():
        i = int(np.argmax(~np.isfinite(t)))
        raise UserInputError(f"{name}: time: non-finite value {t[i]} at index {i}")
    d = np.diff(t)
    if (d <= 0).any():
        i = int(np.argmax(d <= 0))
        what = "repeats (duplicated time)" if d[i] == 0 else "decreases (time is not monotonic)"
        raise UserInputError(f"{name}: time {what} at index {i + 1}: t[{i}] = {t[i]:.9g} s, "
                             f"t[{i + 1}] = {t[i + 1]:.9g} s")
    med = float(np.median(d))
    dev = np.abs(d - med)
    i = int(np.argmax(dev))
    if dev[i] > UNIFORM_TOL * med:
        raise UserInputError(f"{name}: time is not uniformly sampled: step {d[i]:.6g} s at index {i + 1} "
                             f"(t = {t[i + 1]:.9g} s) vs median step {med:.6g} s ({1 / med:.6g} Hz); "
                             f"tolerance {100 * UNIFORM_TOL:g} %")


def _nan_runs(nan: np.ndarray) -> np.ndarray:
    """Runs of True as rows ``[start, stop)``, shape (nruns, 2)."""
    edges = np.diff(np.concatenate(([0], nan.astype(np.int8), [0])))
    return np.column_stack((np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)))


def _check_magnitudes(channels, sensors, units, name: str) -> None:
    for typ, (low, high, low_unit, high_unit) in PLAUSIBLE_PEAK.items():
        peaks = {sid: float(np.nanmax(np.abs(x))) for sid, x in channels.items() if sensors[sid] == typ}
        if not peaks:
            continue
        si = "Pa" if typ == "pressure" else {"displacement": "m", "strain": "-", "acceleration": "m/s²"}[typ]
        how = (f"declare the unit (CSV header '{next(iter(peaks))} [unit]', HDF5 attribute 'units', "
               f"MAT struct 'units' or units=...)")
        for sid, peak in peaks.items():
            if high is not None and peak > high:
                decl = f" after converting from {units[sid]}" if sid in units else ""
                raise UserInputError(f"{name}: channel {sid!r} ({typ}) peaks at {peak:.6g}{decl}, implausible "
                                     f"in SI units ({si}; {_PEAK_REASON[typ]}; limit {high:g}): probably {high_unit}; {how}")
        top = max(peaks, key=peaks.get)
        if low is not None and peaks[top] < low:
            decl = f" after converting from {units[top]}" if top in units else ""
            raise UserInputError(f"{name}: channel {top!r} ({typ}), the largest of its type, peaks at "
                                 f"{peaks[top]:.6g}{decl}, implausible in SI units ({si}; {_PEAK_REASON[typ]}; "
                                 f"below {low:g}): probably {low_unit}; {how}")


def check_rate(data: MeasuredData, min_rate: float) -> None:
    """Reject data sampled below ``min_rate``.

    Parameters
    ----------
    data : MeasuredData
    min_rate : float
        Required sampling rate [Hz], e.g. twice the highest frequency the
        comparison uses.

    Raises
    ------
    UserInputError
        If ``data.rate < min_rate`` (within 1e-9 relative, for rates computed
        from rounded time stamps).
    """
    if data.rate < min_rate * (1 - 1e-9):
        raise UserInputError(f"{data.source}: sampling rate {data.rate:.6g} Hz is below the required "
                             f"{min_rate:.6g} Hz")


# --------------------------------------------------------------------------------------
# Alignment
# --------------------------------------------------------------------------------------
def resample(t_sim: np.ndarray, sim: Mapping[str, np.ndarray], t_new: np.ndarray) -> dict[str, np.ndarray]:
    """Signals linearly interpolated onto a new time base.

    Parameters
    ----------
    t_sim : ndarray, shape (n,)
        Times of ``sim`` [s], strictly increasing.
    sim : mapping of str to ndarray, shape (n,)
        Signals (any unit).
    t_new : ndarray, shape (m,)
        Times to interpolate at [s].

    Returns
    -------
    dict of str to ndarray, shape (m,)
        NaN outside ``[t_sim[0], t_sim[-1]]``. To compare with a measurement
        after :func:`align` returned ``s``: ``resample(t_sim + s, sim, measured.t)``.
    """
    t_sim = np.asarray(t_sim, dtype=float)
    t_new = np.asarray(t_new, dtype=float)
    if t_sim.ndim != 1 or len(t_sim) < 2 or not (np.diff(t_sim) > 0).all():
        raise ValueError("t_sim must be a strictly increasing vector of at least 2 times")
    out = {}
    for key, y in sim.items():
        y = np.asarray(y, dtype=float)
        if y.shape != t_sim.shape:
            raise ValueError(f"signal {key!r} has shape {y.shape}, t_sim has {t_sim.shape}")
        out[key] = np.interp(t_new, t_sim, y, left=np.nan, right=np.nan)
    return out


def align(measured: MeasuredData, t_sim: np.ndarray, sim: Mapping[str, np.ndarray], *,
          max_shift: float | None = None, weights: Mapping[str, float] | None = None) -> float:
    """Time shift between a measured and a simulated passage.

    Sign convention: the returned ``s`` [s] is the delay of the measurement,
    ``measured(t) ≈ sim(t - s)``: an event the simulation shows at time ``τ``
    the measurement shows at ``τ + s``. ``resample(t_sim + s, sim, measured.t)``
    puts the simulation on the measured time base, aligned.

    Method: the simulation is interpolated onto a grid with the measured step
    ``dt`` starting at ``t_sim[0]``. Each common channel (measured and
    simulated, weight > 0) has its baseline removed and is divided by its
    standard deviation (measured: over valid samples; masked samples are then
    set to 0, so they add nothing). The baseline is the median, the quiet
    level before and after the train (a static preload, a gauge offset): the
    mean would be raised by the pulses, and a non-zero level left outside them
    correlates with the zero padding into a tent that pulls the peak toward
    zero lag (0.02 sample for 10-sample pulses; the median keeps this < 1e-3). The weighted sum over channels of the cross-correlations is
    computed in one FFT, its maximum is taken over the lags with
    ``|s| <= max_shift``, and refined to a fraction of a sample by a parabola
    through the peak and its two neighbours. The correlation is not
    re-normalised per lag by the overlap energy: that would let a short
    overlap at an extreme lag win by chance.

    Parameters
    ----------
    measured : MeasuredData
    t_sim : ndarray, shape (n,)
        Simulated times [s], strictly increasing.
    sim : mapping of str to ndarray, shape (n,)
        Simulated signals by sensor id, SI units (only the shapes matter:
        every channel is normalised).
    max_shift : float, optional
        Largest ``|s|`` [s] considered. Default: any shift with overlap.
    weights : mapping of str to float, optional
        Weight per sensor id (default 1 for each common channel); 0 leaves a
        channel out. Ids must be common channels.

    Returns
    -------
    float
        ``s`` [s].

    Raises
    ------
    UserInputError
        No common channel, a bad weight, or ``max_shift`` excluding every lag.
    """
    from scipy.fft import irfft, next_fast_len, rfft

    name = measured.source
    weights = dict(weights or {})
    common = [c for c in measured.channels if c in sim]
    for c, w in weights.items():
        if c not in common:
            raise UserInputError(f"{name}: weight given for {c!r}, which is not a channel of both the "
                                 f"measurement and the simulation{_hint(c, common)}")
        if not (w >= 0 and math.isfinite(w)):
            raise UserInputError(f"{name}: weight of {c!r} must be finite and >= 0, got {w!r}")
    used = [c for c in common if weights.get(c, 1.0) > 0]
    if not used:
        raise UserInputError(f"{name}: no channel in common with the simulation to align on "
                             f"(measured: {', '.join(measured.channels)}; simulated: {', '.join(sim)})")
    if max_shift is not None and not max_shift >= 0:
        raise UserInputError(f"{name}: max_shift must be >= 0 s, got {max_shift!r}")

    dt = measured.dt
    t_sim = np.asarray(t_sim, dtype=float)
    ns = int(math.floor((t_sim[-1] - t_sim[0]) / dt * (1 + 1e-12))) + 1   # 1e-12: keep the last point when exact
    grid = np.minimum(t_sim[0] + dt * np.arange(ns), t_sim[-1])   # round-off must not step past the end
    nm = len(measured.t)
    nfft = next_fast_len(nm + ns - 1, real=True)
    spectrum = np.zeros(nfft // 2 + 1, dtype=complex)
    sim_on_grid = resample(t_sim, {c: sim[c] for c in used}, grid)
    for c in used:
        valid = measured.mask[c]
        m = np.where(valid, measured.channels[c], 0.0)
        m_std = np.std(measured.channels[c][valid])
        s = sim_on_grid[c]
        if not np.isfinite(s).all():
            raise UserInputError(f"{name}: simulated channel {c!r} has non-finite values; cannot align")
        s_std = np.std(s)
        if m_std == 0 or s_std == 0:
            continue   # a constant channel carries no timing information
        m = np.where(valid, (m - np.median(measured.channels[c][valid])) / m_std, 0.0)
        s = (s - np.median(s)) / s_std
        spectrum += weights.get(c, 1.0) * rfft(m, nfft) * np.conj(rfft(s, nfft))
    cc = irfft(spectrum, nfft)
    # cc[L] = sum_k m[k+L] s[k]; lags L = -(ns-1) ... nm-1, negative ones wrapped to the end
    corr = np.concatenate((cc[nfft - (ns - 1):], cc[:nm])) if ns > 1 else cc[:nm]
    lags = np.arange(-(ns - 1), nm)
    shifts = measured.t[0] - grid[0] + lags * dt
    allowed = np.ones(len(lags), bool) if max_shift is None else np.abs(shifts) <= max_shift
    if not allowed.any():
        raise UserInputError(f"{name}: max_shift = {max_shift:g} s excludes every shift between the measured "
                             f"and the simulated passage ({shifts[0]:.6g} ... {shifts[-1]:.6g} s)")
    k = int(np.flatnonzero(allowed)[np.argmax(corr[allowed])])
    if not corr[k] > 0:
        raise UserInputError(f"{name}: measured and simulated signals do not correlate (no positive peak)")
    delta = 0.0
    if 0 < k < len(corr) - 1:
        y0, y1, y2 = corr[k - 1], corr[k], corr[k + 1]
        denom = y0 - 2 * y1 + y2
        if denom < 0:
            delta = float(np.clip(0.5 * (y0 - y2) / denom, -0.5, 0.5))
    s = float(shifts[k] + delta * dt)
    if max_shift is not None:
        s = float(np.clip(s, -max_shift, max_shift))
    return s


# --------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------
def write_measured(path: str | Path, data_t: np.ndarray, channels: Mapping[str, np.ndarray],
                   units: Mapping[str, str] | None = None) -> Path:
    """Write sensor data as CSV, HDF5 or MATLAB v5 ``.mat`` (by suffix).

    Layouts are those :func:`read_measured` reads: CSV header ``time,A1 [unit],...``
    (time with 17 significant digits so it round-trips exactly, channels with 12,
    more than any sensor resolves); HDF5 ``/time`` and ``/sensors/<id>`` with a
    ``units`` attribute; MAT variables ``time``, ``<id>`` (column vectors) and
    the struct ``units``.

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
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise UserInputError(f"{path}: unsupported measured-data format {path.suffix or '(no suffix)'!r}; "
                             f"supported: {', '.join(SUFFIXES)}")
    t = np.asarray(data_t, dtype=float)
    cols = {k: np.asarray(v, dtype=float) for k, v in channels.items()}
    for k, v in cols.items():
        if k == "time" or v.shape != t.shape:
            raise ValueError(f"channel {k!r}: shape {v.shape} vs time {t.shape} (or the reserved name 'time')")
    units = dict(units or {})
    if suffix == ".csv":
        head = ["time" + (f" [{units['time']}]" if "time" in units else "")]
        head += [k + (f" [{units[k]}]" if k in units else "") for k in cols]
        with open(path, "w", newline="") as fh:
            fh.write(",".join(head) + "\n")
            data = np.column_stack([t] + list(cols.values())) if cols else t[:, None]
            fmt = ["%.17g"] + ["%.12g"] * len(cols)
            np.savetxt(fh, data, delimiter=",", fmt=fmt)
    elif suffix in (".h5", ".hdf5"):
        import h5py
        with h5py.File(path, "w") as f:
            f["time"] = t
            f["time"].attrs["units"] = units.get("time", "s")
            g = f.create_group("sensors")
            for k, v in cols.items():
                g[k] = v
                if k in units:
                    g[k].attrs["units"] = units[k]
    else:
        import scipy.io
        bad = [k for k in cols if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]{0,62}", k) or k == "units"]
        if bad:
            raise ValueError(f"sensor ids {bad} are not valid MATLAB variable names (or are 'units')")
        mdict = {"time": t, **cols}
        if units:
            mdict["units"] = dict(units)
        scipy.io.savemat(str(path), mdict, oned_as="column")
    return path
