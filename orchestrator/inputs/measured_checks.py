"""Checks of measured sensor data, and the :class:`MeasuredData` they produce.

Sensor data, simulated and measured alike (DESIGN §4.3), is a ``time`` column
[s] and one column per sensor id in SI units: ``pressure`` [Pa],
``displacement`` [m], ``acceleration`` [m/s²], ``strain`` [-].
:func:`check_measured` (which :func:`orchestrator.inputs.measured.read_measured` calls
after reading a file) returns a :class:`MeasuredData` or raises
:class:`~orchestrator.inputs.errors.UserInputError` with one line naming the file, the
channel and the offending value or index. The checks, in order, and why:

1. **Channels.** Columns that are not sensors of the layout are ignored (noted).
   A ``required`` sensor that is absent is an error listing every missing id
   with close matches (:mod:`difflib`); an absent sensor that is not required
   is dropped (noted). A file with no sensor of the layout at all is an error.
2. **Time.** At least :data:`MIN_SAMPLES` samples (a measured file: ``min_samples``,
   100 by default); sampled at :data:`MIN_RATE` or faster (else the time is probably in
   milliseconds); no NaN; strictly increasing
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
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from orchestrator.inputs.errors import UserInputError
from orchestrator.inputs.errors import did_you_mean as _hint
from track.sensors import SENSOR_TYPES  # the one list of sensor types (DESIGN §4.3)

__all__ = [
    "SENSOR_TYPES",
    "UNIT_FACTORS",
    "PLAUSIBLE_PEAK",
    "MIN_SAMPLES",
    "MIN_RATE",
    "UNIFORM_TOL",
    "MAX_NAN_FRACTION",
    "MAX_GAP_SAMPLES",
    "MeasuredData",
    "check_layout",
    "check_measured",
    "check_rate",
]

MIN_SAMPLES = 3            # a step and a check of its uniformity need at least two intervals
# A passage record sampled below this is not one, or its time is not in seconds: at
# 120 km/h sleepers 0.6 m apart pass at 55 Hz, so a record that shows them needs
# > 110 Hz (Nyquist); field systems sample at 0.5-20 kHz. Time in milliseconds read as
# seconds gives 1-20 Hz.
MIN_RATE = 100.0           # Hz
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
        return _mean_step(self.t)

    @property
    def rate(self) -> float:
        """Sampling rate [Hz]."""
        return 1.0 / self.dt


def _mean_step(t: np.ndarray) -> float:
    """Mean step [s] of the times ``t``, shape (nt,), nt >= 2."""
    return float((t[-1] - t[0]) / (len(t) - 1))


@dataclass(frozen=True)
class _TimeBase:
    """The checked time base a channel is checked against."""

    t: np.ndarray  # shape (nt,), [s], strictly increasing and uniform
    dt: float  # mean step [s]
    max_gap: float  # longest NaN gap [s] that is masked rather than rejected


# --------------------------------------------------------------------------------------
# check_measured and its stages
# --------------------------------------------------------------------------------------
def check_measured(columns: Mapping[str, np.ndarray], sensors: Mapping[str, str], *, source: str = "<arrays>",
                   required: Sequence[str] | None = None, max_gap: float | None = None,
                   units: Mapping[str, str] | None = None, ignored: Sequence[str] = (),
                   min_samples: int = MIN_SAMPLES) -> MeasuredData:
    """Check columns already in memory and build a :class:`MeasuredData`.

    The checks of :func:`orchestrator.inputs.measured.read_measured` (which calls this
    after reading), usable on signals that never were a file (e.g. a synthetic
    measurement). The caller's arrays are not modified.

    Parameters
    ----------
    columns : mapping of str to array_like, shape (n,)
        ``"time"`` [s] and signals by name; names not in ``sensors`` are ignored.
    sensors, required, max_gap, units
        As in :func:`orchestrator.inputs.measured.read_measured`.
    source : str
        Name used in messages and kept in the result.
    ignored : sequence of str
        Names the reader already skipped (non-numeric variables, groups); noted.
    min_samples : int
        Fewest samples accepted (at least :data:`MIN_SAMPLES`); a measured file asks for
        more (:data:`orchestrator.inputs.measured.MIN_RECORD_SAMPLES`).

    Returns
    -------
    MeasuredData
    """
    name = source
    check_layout(sensors, name)
    units = dict(units or {})
    present, notes = _select_channels(columns, sensors, required, ignored, name)   # 1. channels
    n = int(np.size(columns["time"]))
    if n < max(min_samples, MIN_SAMPLES):
        raise UserInputError(f"{name}: {n} samples; at least {max(min_samples, MIN_SAMPLES)} are needed "
                             "(each channel's RMSE rests on them)")
    base, time_note = _time_base(columns["time"], units.get("time"), max_gap, name)   # 2. time
    notes += [time_note] if time_note else []
    channels, mask = {}, {}
    for sid in present:   # 3. gaps, 4. units
        channels[sid], mask[sid], channel_notes = _checked_channel(columns[sid], sid, sensors[sid], units.get(sid),
                                                                   base, name)
        notes += channel_notes
    _check_magnitudes(channels, sensors, units, name)   # 4. plausibility of the SI magnitudes
    return MeasuredData(t=base.t, channels=channels, mask=mask, source=name, notes=tuple(notes))


def _select_channels(columns: Mapping[str, np.ndarray], sensors: Mapping[str, str],
                     required: Sequence[str] | None, ignored: Sequence[str], name: str) -> tuple[list[str], list[str]]:
    """Check 1: the sensors of the layout in ``columns`` (layout order) and notes on what is ignored or dropped.

    Raises
    ------
    UserInputError
        No ``time`` column, a required sensor not in the layout or not in ``columns``, or
        no sensor of the layout at all.
    """
    notes: list[str] = []
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
    return present, notes


def _time_base(values, unit: str | None, max_gap: float | None, name: str) -> tuple[_TimeBase, str]:
    """Check 2: the ``time`` column -> checked time base [s] and the unit-conversion note ('' when none).

    Raises
    ------
    UserInputError
        An unknown time unit, a time vector :func:`_check_time` rejects, or ``max_gap < 0``.
    """
    t = _as_vector(values, name, "time")
    t_factor, note = _unit_factor(unit, "time", "time", name)
    if note:
        t = t * t_factor
    _check_time(t, name)
    dt = _mean_step(t)
    if 1.0 / dt < MIN_RATE:
        hint = ("; if the time column is in milliseconds, declare it (CSV header 'time [ms]', HDF5 attribute "
                "'units', MAT struct 'units' or units=...)") if unit is None else ""
        raise UserInputError(f"{name}: time step {dt:.6g} s ({1.0 / dt:.6g} Hz) is too coarse for a passage record "
                             f"(at least {MIN_RATE:g} Hz: sleepers pass at ~55 Hz at 120 km/h){hint}")
    gap_limit = MAX_GAP_SAMPLES * dt if max_gap is None else float(max_gap)
    if not gap_limit >= 0.0:
        raise UserInputError(f"{name}: max_gap must be >= 0 s, got {max_gap!r}")
    return _TimeBase(t, dt, gap_limit), note


def _checked_channel(values, sid: str, quantity: str, unit: str | None, base: _TimeBase,
                     name: str) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Checks 2-4 of one sensor: length, unit -> SI, gaps.

    Returns
    -------
    x : ndarray, shape (nt,)
        The signal in SI units (a new array), NaN where masked.
    valid : ndarray of bool, shape (nt,)
        False where masked.
    notes : list of str
        The conversion and the masking, where done.
    """
    x = _as_vector(values, name, sid)
    t = base.t
    if len(x) != len(t):
        span = t[-1] - t[0]
        raise UserInputError(
            f"{name}: channel {sid!r} has {len(x)} samples but time has {len(t)} (implied rates "
            f"{(len(x) - 1) / span:.6g} Hz vs {(len(t) - 1) / span:.6g} Hz): resample it onto the time base")
    factor, note = _unit_factor(unit, quantity, sid, name)
    notes = [note] if note else []
    x = x * factor   # a new array: the caller's is left alone
    nan, gap_note = _masked_gaps(x, sid, base, name)
    notes += [gap_note] if gap_note else []
    return x, ~nan, notes


def _masked_gaps(x: np.ndarray, sid: str, base: _TimeBase, name: str) -> tuple[np.ndarray, str]:
    """Check 3 of channel ``sid``: ``x`` -> where it is NaN (masked) and the note ('' when nothing is).

    Raises
    ------
    UserInputError
        ±inf anywhere, more than :data:`MAX_NAN_FRACTION` NaN, or a NaN gap longer than ``base.max_gap``.
    """
    t, dt, gap_limit = base.t, base.dt, base.max_gap
    bad = np.isinf(x)
    if bad.any():
        i = int(np.argmax(bad))
        raise UserInputError(f"{name}: channel {sid!r}: non-finite value {x[i]} at index {i} (t = {t[i]:.6g} s)")
    nan = np.isnan(x)
    if not nan.any():
        return nan, ""
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
    return nan, (f"{sid}: masked {int(nan.sum())} NaN samples in {len(runs)} gap(s) of at most "
                 f"{int(lengths.max())} samples, first at t = {t[runs[0, 0]]:.6g} s")


# --------------------------------------------------------------------------------------
# Helpers of the checks
# --------------------------------------------------------------------------------------
def check_layout(sensors: Mapping[str, str], name: str) -> None:
    """Reject a sensor mapping (id -> type) with an unknown type or a sensor named ``time``."""
    for sid, typ in sensors.items():
        if typ not in SENSOR_TYPES:
            raise UserInputError(f"{name}: sensor {sid!r} has type {typ!r}{_hint(str(typ), SENSOR_TYPES)}; "
                                 f"expected one of {', '.join(SENSOR_TYPES)}")
        if sid == "time":
            raise UserInputError(f"{name}: 'time' cannot be a sensor id")


def _as_vector(values, name: str, col: str) -> np.ndarray:
    """Column ``col`` as a float vector, shape (n,) (singleton axes squeezed out)."""
    arr = np.asarray(values, dtype=float)
    if arr.ndim != 1:
        squeezed = np.squeeze(arr)
        if squeezed.ndim != 1:
            raise UserInputError(f"{name}: {col!r} has shape {arr.shape}, expected a vector")
        arr = squeezed
    return arr


def _normalise_unit(unit: str) -> str:
    """A unit string as :data:`UNIT_FACTORS` spells it: µ/μ -> u, ² -> 2, no blanks, no '^'."""
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
    """Check 2 on the time vector [s] (of at least MIN_SAMPLES samples): finite, strictly increasing, uniform."""
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
    """Check 4: each type's peak magnitude in SI within :data:`PLAUSIBLE_PEAK` (else: probably another unit)."""
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
                                     f"in SI units ({si}; {_PEAK_REASON[typ]}; limit {high:g}): "
                                     f"probably {high_unit}; {how}")
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

