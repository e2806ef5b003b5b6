"""Measured sensor data: read, check, align with a simulation, write.

Sensor data, simulated and measured alike (DESIGN §4.3), is a ``time`` column
[s] and one column per sensor id in SI units: ``pressure`` [Pa],
``displacement`` [m], ``acceleration`` [m/s²], ``strain`` [-].
:func:`read_measured` reads a measured file and checks it; the parts live in

* :mod:`orchestrator.inputs.measured_files`: the formats (CSV, HDF5, MATLAB ``.mat``),
  their readers and :func:`write_measured`;
* :mod:`orchestrator.inputs.measured_checks`: the checks, in order and with their
  reasons (channels, time, gaps, units and plausible magnitudes), :func:`check_measured`,
  :func:`check_rate` and :class:`MeasuredData`;
* :mod:`orchestrator.inputs.measured_alignment`: :func:`align` (time shift between a
  measured and a simulated passage) and :func:`resample`.

Every name is importable from here.
"""
from __future__ import annotations

import warnings
from pathlib import Path
from typing import Mapping, Sequence

from orchestrator.inputs.errors import UserInputError, UserInputWarning
from orchestrator.inputs.measured_alignment import align, resample
from orchestrator.inputs.measured_checks import (
    MAX_GAP_SAMPLES,
    MAX_NAN_FRACTION,
    MIN_RATE,
    MIN_SAMPLES,
    PLAUSIBLE_PEAK,
    SENSOR_TYPES,
    UNIFORM_TOL,
    UNIT_FACTORS,
    MeasuredData,
    check_layout,
    check_measured,
    check_rate,
)
from orchestrator.inputs.measured_files import SUFFIXES, check_suffix, read_columns, write_measured

__all__ = [
    "SENSOR_TYPES",
    "SUFFIXES",
    "UNIT_FACTORS",
    "PLAUSIBLE_PEAK",
    "MIN_SAMPLES",
    "MIN_RATE",
    "MIN_RECORD_SAMPLES",
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

# A measured passage file needs at least this many samples: the comparison rests on each
# channel's RMSE, whose relative standard error is about 1/sqrt(2 n) for n independent
# samples (7 % at 100; 22 % at 10), and a 0.5 s passage at >= 1 kHz has 500+.
MIN_RECORD_SAMPLES = 100


def read_measured(path: str | Path, sensors: Mapping[str, str], *, required: Sequence[str] | None = None,
                  max_gap: float | None = None, units: Mapping[str, str] | None = None,
                  min_samples: int = MIN_RECORD_SAMPLES) -> MeasuredData:
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
    min_samples : int
        Fewest samples a file may hold (default :data:`MIN_RECORD_SAMPLES`).

    Returns
    -------
    MeasuredData

    Raises
    ------
    UserInputError
        For every problem listed in :mod:`orchestrator.inputs.measured_checks`; the
        message is one line naming the file, the channel and the offending value or index;
        also a file of fewer than ``min_samples`` samples.

    Warns
    -----
    UserInputWarning
        Sensors of the layout that the file lacks (they are dropped from the comparison).
    """
    path = Path(path)
    name = str(path)
    check_suffix(path)
    check_layout(sensors, name)
    if not path.is_file():
        raise UserInputError(f"{name}: measured-data file not found")
    raw = read_columns(path, name)
    declared = {**raw.units, **dict(units or {})}
    data = check_measured(raw.columns, sensors, source=name, required=required, max_gap=max_gap,
                          units=declared, ignored=raw.skipped, min_samples=min_samples)
    absent = [s for s in sensors if s not in data.channels]
    if absent:
        warnings.warn(f"{name}: sensors of the layout not in the file, left out of the comparison: "
                      f"{', '.join(absent)}", UserInputWarning, stacklevel=2)
    return data

