"""Track FMU slave: ``Track`` (FMI 2.0 co-simulation, pythonfmu), a thin map onto ``track.cosim.TrackCosim``.

The scenario's ``track:`` section is baked into the FMU at build time as
``resources/track_fmu.json`` (:func:`resource_payload`, written by
``fmus.build.build_track_fmu``), together with the number of wheels, the
defaults of the run parameters and the resolved sensors (optional key ``sensors``).
The slave reads it from its resources folder (``self.resources``, which
pythonfmu passes to every instance: the FMU's
``resources/`` at run time, the staging folder at build time), so the variable
list, their start values and the model all come from one file.

Ports (DESIGN §4.4, the vehicle's with causality mirrored), wheels i = 1..n,
front wheelset left, right, then the next:

* inputs  ``wheel{i}_x`` [m]     track coordinate of the wheel
          ``wheel{i}_z`` [m]     vertical position of the wheel's contact point, upward +
          ``wheel{i}_vz`` [m/s]  its velocity
* outputs ``wheel{i}_Fz`` [N]    contact force on the wheel, upward + (initial="approx",
                                 start value = ``static_wheel_load``)
          ``wheel{i}_Fz_coupling`` [N]  the force to feed the vehicle: ``wheel{i}_Fz``, or with
                                 ``extrapolate_force`` extrapolated to the next step's middle
          ``wheel{i}_Fz_rail`` [N]  part carried by the running / wing rail
          ``wheel{i}_Fz_nose`` [N]  part carried by the crossing nose
          ``wheel{i}_rail_z`` [m]   rail deflection under the wheel, upward + (0 until the first step)
* outputs, one per sensor of the baked sensor layout (DESIGN §4.3, §4.4; see "Sensor
  outputs" below), named by the sensor id: ``<id>`` in Pa (pressure), m/s2
  (acceleration), - (strain) or m (displacement), and for each displacement sensor
  also ``<id>_acc`` [m/s2], the signal of its accelerometer
* parameters, variability "fixed" (read at exitInitializationMode, where the model
  is rebuilt from the baked parameters with these overrides; ``track.model``'s
  in-process cache of reduced bodies makes a second instance or a re-init cheap):
  ``speed`` [m/s], ``static_wheel_load`` [N], ``h1`` [-] (ballast stiffness
  scale), ``h2`` [-] (rail-pad stiffness scale), ``impact_angle`` [rad],
  ``pad_stiffness`` [N/m], ``ballast_stiffness_per_length`` [N/m2] (N/m per m),
  ``void_sleeper`` (Integer; -1: no change; else the void under that sleeper is
  added or replaced by ``void_gap_1`` .. ``void_gap_6`` [m]), ``extrapolate``,
  ``extrapolate_force``, ``auto_offset`` (Boolean), ``record_every`` (Integer, 0: no recording),
  ``record_columns`` (String: empty records every column of q, v and a; else JSON
  ``{"q": [i, ...], "v": [...], "a": [...]}``, the columns of each field to record, a field
  left out not recorded: a host that post-processes a few bodies and sensors records
  what it reads, not the whole state); and, tunable, ``record_file`` (String, read at
  terminate: if not empty the recorded states are written there as ``.npz``).
  The record is preallocated for the host's stop time (``setupExperiment``) when it gives
  one, and written to the file without a copy.
* outputs, monitoring: the integrator's work counters ``track_steps``, ``linear_solves``,
  ``contact_iterations``, ``passes``, ``factorizations`` (Integer), ``python_steps`` (steps taken
  in Python, below) and the wall times ``wall_statics``, ``wall_factor`` [s] (0 until the first step)

Compiled steps (``fmus.fast``, ``track.unit_step``): after its first step the instance registers
with the FMU's C shim a compiled step (a numba C function on the TrackCosim's state buffers) and
its wheel ports. From then on the shim sets the inputs, takes the steps and reads the wheel outputs
without entering Python — the same kernel on the same state, so the same numbers to the last bit
— and hands a step to Python only when it must (a wheel entering a rail element whose data are
not loaded: Python loads them and the compiled step goes on; a bad input, a step size change, a
failing or diverged step, a full record: Python takes that step and reports as below). Any other
call (sensor and counter outputs, FMU state, terminate, ...) first writes the compiled steps'
state back into the Python objects. ``XPANEL_FMU_FAST=0`` in the host's environment turns it off.

Lazy construction: ``TrackCosim`` needs the communication step, which the FMU
learns at its first ``doStep``; it is built there, and its first step puts the
track in static equilibrium under the static wheel loads at the wheels' input
positions.  The step is fixed from then on: a ``doStep`` with another step size is
discarded with a log message, and the model description says so
(``canHandleVariableCommunicationStepSize="false"``).  A wheel whose track coordinate
lies outside the modelled panel (before the first or after the last sleeper) makes the
step discarded with a message naming the wheel: the track's response there is that of
a free rail end, not of a track.  A model failure (``ConvergenceError``: state
unchanged; ``DivergenceError``: the state is lost, every later step is discarded
until an FMU state is restored) gives fmi2Discard with the message
(``fmus.base``).  The FMU state holds the ``TrackCosim`` state, its step and the
lazy-construction flag; recorded samples are not part of it (a restore truncates
the record to the restored length).

Sensor outputs: the sensors are resolved on the scenario's track at build time
(``orchestrator.cosim.build_job``: the scenario's ``sensors:`` layout or the default one,
``orchestrator.inputs.sensor_layout.resolve``) and baked into ``track_fmu.json`` as a list of
``track.sensors.Sensor`` (body name, coordinate, ...), so the FMU reads no layout file at
run time.  Their rows (``track.sensors.compile_sensors``) are compiled on the model
whenever it is (re)built, since h1, h2, voids, ... change the ballast bushings but not the
bodies a sensor sits on.  A sensor output is the value at the current state, 0 until
the first step (as ``wheel{i}_rail_z``): pressure from the ballast bushings' pressures
under the sensor (``model.ballast.pressure``), acceleration and strain from the rows on
the accelerations and the displacements.  A displacement sensor outputs the displacement
itself (its ``displacement_row`` on q): the field team reconstructs displacements from
the accelerometer with a zero-phase high-pass (``track.sensors.displacement_from_acceleration``),
which no causal FMU can apply; the offline pipeline (``orchestrator.cosim.sensing``, from the
recorded states) applies it to the accelerometer signal over the whole record, and a host
of this FMU can do the same with the output ``<id>_acc``.  The
values are computed from the rows restricted to their non-zero columns (:class:`SensorReader`:
three gathers and one matrix-vector product), when an output is first read after a step
(a run that reads no sensor pays nothing for them).
"""
from __future__ import annotations

import dataclasses
import json
import math
import os
from pathlib import Path
from typing import Any, Dict, Sequence

import numpy as np
from pythonfmu.default_experiment import DefaultExperiment
from pythonfmu.enums import Fmi2Causality, Fmi2Initial, Fmi2Variability
from pythonfmu.variables import Integer, Real, String

from .base import UNITS, CosimSlave
from .fast import FastPath, fast_enabled, shim_library

try:  # inside a built FMU the model package is bundled next to this module
    from .track import ballast as _ballast
    from .track import cache as _cache
    from .track import cosim as _cosim
    from .track import dynamics as _dynamics
    from .track import fused as _fused
    from .track import model as _model
    from .track import params as _params
    from .track import sensors as _sensors
    from .track import unit_step as _unit_step
except ModuleNotFoundError as _exc:  # source tree: src/ on sys.path
    if _exc.name != f"{__package__}.track":
        raise   # a dependency of the bundled package is missing (scipy, ...): say which
    from track import ballast as _ballast
    from track import cache as _cache
    from track import cosim as _cosim
    from track import dynamics as _dynamics
    from track import fused as _fused
    from track import model as _model
    from track import params as _params
    from track import sensors as _sensors
    from track import unit_step as _unit_step

# ballast bed stiffness is given per metre of sleeper: N/m per m; accelerations (fmus.base's unit registry)
UNITS.setdefault("N/m2", {"kg": 1, "m": -1, "s": -2})
UNITS.setdefault("m/s2", {"m": 1, "s": -2})

RESOURCE_FILE = "track_fmu.json"   # in the FMU's resources folder
RESOURCE_FORMAT = "xpanel-track-fmu/1"
N_VOID_GAPS = 6                    # gaps at 6 equidistant points along a sleeper (DESIGN §3)
STEP_RTOL = 1e-9                   # step sizes closer than this (relative) count as equal: libcosim
                                   # converts its integer-ns clock and hands over h(1 + 1e-12)
SIDE = ("left", "right")
COUNTER_OUTPUTS = {   # Integer output -> (attribute of track.dynamics.Counters, what it counts)
    "track_steps": ("steps", "time steps of the track integrator"),
    "linear_solves": ("solves", "linear solves with the step matrix"),
    "contact_iterations": ("contact_newton", "Newton sweeps of the Hertz contact forces"),
    "passes": ("iterations", "modified-Newton passes of the track steps"),
    "factorizations": ("factorizations", "factorizations of the step matrix"),
}
SENSOR_UNITS = {"pressure": "Pa", "acceleration": "m/s2", "strain": "-", "displacement": "m"}
ACCELEROMETER_SUFFIX = "_acc"      # <id>_acc: the accelerometer signal of displacement sensor <id>
RUN_DEFAULTS = {"speed": 33.333, "static_wheel_load": 98100.0, "extrapolate": True,
                "auto_offset": True, "record_every": 0, "extrapolate_force": True}   # DESIGN §4.2 example: 120 km/h, 20 t axle


def resource_payload(params: "_params.TrackParams", n_wheels: int, sensors: Sequence["_sensors.Sensor"] = (),
                     **defaults: Any) -> bytes:
    """The baked resource file of a track FMU (JSON).

    Parameters
    ----------
    params : TrackParams
        The scenario's track section.
    n_wheels : int
        Number of wheels (bogie 4, quarter vehicle 2).
    sensors : sequence of track.sensors.Sensor
        The sensors, resolved on a model of ``params`` (``orchestrator.inputs.sensor_layout.resolve``);
        one output each (see the module docstring).  Empty: no sensor outputs.
    **defaults
        Defaults of the run parameters, keys of :data:`RUN_DEFAULTS`: ``speed`` [m/s],
        ``static_wheel_load`` [N], ``extrapolate``, ``auto_offset`` (bool),
        ``record_every`` (int).

    Returns
    -------
    bytes
    """
    unknown = set(defaults) - set(RUN_DEFAULTS)
    if unknown:
        raise TypeError(f"unknown track FMU default(s) {sorted(unknown)}; known: {sorted(RUN_DEFAULTS)}")
    if int(n_wheels) < 1:
        raise ValueError(f"n_wheels = {n_wheels!r} must be >= 1")
    sensors = tuple(sensors)
    ids = [s.id for s in sensors]
    if len(set(ids)) != len(ids):
        raise ValueError(f"sensor ids must be unique, got {ids}")
    bad = [f"{s.id}: {s.type!r}" for s in sensors if s.type not in SENSOR_UNITS]
    if bad:
        raise ValueError(f"unknown sensor type(s) {bad}; known: {sorted(SENSOR_UNITS)}")
    values = dict(RUN_DEFAULTS, **defaults)
    payload = {"format": RESOURCE_FORMAT, "n_wheels": int(n_wheels),
               "track": dataclasses.asdict(params),
               "sensors": [dataclasses.asdict(s) for s in sensors],
               "defaults": {"speed": float(values["speed"]),
                            "static_wheel_load": float(values["static_wheel_load"]),
                            "extrapolate": bool(values["extrapolate"]),
                            "auto_offset": bool(values["auto_offset"]),
                            "record_every": int(values["record_every"]),
                            "extrapolate_force": bool(values["extrapolate_force"])}}
    return json.dumps(payload, indent=1).encode("utf-8")


WHEEL_OUTPUTS = ("Fz", "Fz_coupling", "Fz_rail", "Fz_nose", "rail_z")   # per wheel, in get_real's bulk order


class StepSizeError(ValueError):
    """A communication step differs from the first one (the track FMU is fixed-step)."""


class SensorReader:
    """Values of the sensor outputs at one track state, a few small products per call.

    The rows of ``track.sensors.compile_sensors`` span all n generalized coordinates
    (1741 on the 40-sleeper turnout) but touch few of them (a point on a Craig-Bampton
    body reads its boundary and modal coordinates: about 200 for the default layout's
    20 sensors).  They are restricted once to their non-zero columns and stacked, so a
    reading gathers those entries of q and a, evaluates the bushings under the pressure
    cells only, and does one (ns_out, n_used) matrix-vector product, the arithmetic of
    ``track.sensors.sensor_signals`` at one time (up to the order of summation), in compiled code
    that the FMU's compiled steps call too (``track.unit_step.sensor_read``).

    Output rows, in this order: one per sensor (pressure: bushing pressures; acceleration:
    row on a; strain: row on q; displacement: ``track.sensors.displacement_row`` on q,
    see the module docstring), then one per displacement sensor, its accelerometer (the
    same point's row on a).

    Parameters
    ----------
    model : TrackModel
    sensors : sequence of track.sensors.Sensor

    Raises
    ------
    ValueError
        From ``compile_sensors``: a sensor on a body the model does not have, ...
    """

    def __init__(self, model: "_model.TrackModel", sensors: Sequence["_sensors.Sensor"]):
        compiled = _sensors.compile_sensors(model, sensors)
        self.sensors = compiled.sensors
        disp = [i for i, s in enumerate(self.sensors) if s.type == "displacement"]
        Cq = compiled.Cq.copy()
        Ca = np.vstack([compiled.Ca, compiled.Ca[disp]])   # accelerometer rows of the displacement sensors
        for i in disp:   # the displacement itself, not its accelerometer
            s = self.sensors[i]
            Cq[i] = _sensors.displacement_row(model, s.body, s.coord)
            Ca[i] = 0.0
        n_out = len(self.sensors) + len(disp)
        Cq = np.vstack([Cq, np.zeros((len(disp), model.n))])
        Pb = np.vstack([compiled.Pb, np.zeros((len(disp), compiled.Pb.shape[1]))])
        self.cols_q = np.flatnonzero(np.any(Cq != 0.0, axis=0))
        self.cols_a = np.flatnonzero(np.any(Ca != 0.0, axis=0))
        used = np.flatnonzero(np.any(Pb != 0.0, axis=0))
        bal = model.ballast   # the bushings under the pressure cells (arrays all of length nb)
        self.ballast = _ballast.Ballast(**{f.name: getattr(bal, f.name)[used] for f in dataclasses.fields(bal)})
        self.C = np.ascontiguousarray(np.hstack([Cq[:, self.cols_q], Ca[:, self.cols_a], Pb[:, used]]))
        self._x = np.empty(self.C.shape[1])   # gathered q, a entries and bushing pressures
        self.values = np.zeros(n_out)
        b = self.ballast
        # track.unit_step.sensor_read's arrays: the compiled steps (fmus.fast) evaluate the same function
        self.arrays = (*(np.ascontiguousarray(x, dtype=np.int64) for x in (self.cols_q, self.cols_a, b.dof)),
                       *(np.ascontiguousarray(x, dtype=float) for x in (b.k, b.c, b.gap, b.area)), self.C, self._x)

    def read(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """Sensor values at the state (q [m], v [m/s], a [m/s2], shape (n,)): the pressures by the law of
        ``track.ballast.Ballast.pressure`` and one product, in compiled code (``track.unit_step.sensor_read``).

        Returns
        -------
        ndarray, shape (n_out,)
            SI units; a view of a buffer that the next call overwrites.
        """
        _unit_step.sensor_read(np.ascontiguousarray(q, dtype=float), np.ascontiguousarray(v, dtype=float),
                               np.ascontiguousarray(a, dtype=float), *self.arrays, self.values)
        return self.values


class Track(CosimSlave):
    """Reduced track with wheel–rail contact; n wheels (see module docstring)."""

    author = "crossing-panel co-simulation project"
    version = "0.1"
    description = ("Crossing-panel track (Craig-Bampton reduced rails and sleepers, rail pads, bi-linear "
                   "ballast) with Hertz wheel-rail contact on wing rail and nose; vertical dynamics")
    default_experiment = DefaultExperiment(start_time=0.0, stop_time=1.0, step_size=2e-5)

    def to_xml(self, model_options=None):
        # the step is fixed at the first doStep (module docstring)
        return super().to_xml({"canHandleVariableCommunicationStepSize": False, **(model_options or {})})

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._read_baked()
        n = self._n
        self._inp = np.zeros(3 * n)   # the inputs x | z | vz (the fast path's input buffer; never rebound)
        self._x, self._z, self._vz = self._inp[:n], self._inp[n:2 * n], self._inp[2 * n:]
        self._fast = None         # FastPath once registered (after the first step); False: none here
        self._unit = None         # track.unit_step.UnitSteps of the current TrackCosim (the fast path's)
        self._ctx = None          # its arguments' table for the compiled C step (track.unit_cfunc.pack)
        self._pack = None         # track.unit_cfunc.pack, once that module is loaded (_register_fast)
        self._ctx_record = None   # the record arrays packed into it
        self._model = None        # TrackModel, built at exitInitializationMode
        self._built = None        # the TrackParams it was built from
        self._cosim = None        # TrackCosim, built at the first doStep (needs the step)
        self._t_first = None      # time of the first doStep [s] (TrackCosim's time 0)
        self._reader = None       # SensorReader of the model, built with it
        self._sensor_values = None  # its values at the current state; None: not read since the last step
        self.stop_time = None     # the host's stop time [s] (setupExperiment), to size the record
        self._cosim_columns = ""  # record_columns of the TrackCosim built last
        self._add_model_parameters()
        self._add_run_parameters()
        self._add_wheel_ports()
        self._add_counter_outputs()
        self._add_sensor_outputs()
        # the wheel outputs' value references -> position in _wheel_values (get_real's bulk read)
        order = {f"wheel{i + 1}_{k}": j * self._n + i for j, k in enumerate(WHEEL_OUTPUTS) for i in range(self._n)}
        self._wheel_slot = {v.value_reference: order[v.name] for v in self.vars.values() if v.name in order}
        self._bulk: dict = {}     # tuple of value references -> slots (None: not all of them wheel outputs)

    def _read_baked(self) -> None:
        """The baked resource file: track parameters, sensors, wheel count and the parameters'
        start values (the model parameters' from the baked track: the defaults change nothing)."""
        if self.resources is None:
            raise FileNotFoundError(f"the track FMU needs its resources folder (with {RESOURCE_FILE})")
        baked = json.loads((Path(self.resources) / RESOURCE_FILE).read_text(encoding="utf-8"))
        if baked.get("format") != RESOURCE_FORMAT:
            raise ValueError(f"{RESOURCE_FILE}: format {baked.get('format')!r}, expected {RESOURCE_FORMAT!r}")
        self._baked = p = _params.track_params_from_dict(baked["track"])
        self._sensors = tuple(_sensors.Sensor(**d) for d in baked.get("sensors", ()))
        self._n = int(baked["n_wheels"])
        voids = p.ballast.voids
        first_void = voids[0] if voids else None   # defaults reproduce it: replacing it changes nothing
        self._values: Dict[str, Any] = dict(baked["defaults"])
        self._values.update(
            h1=p.ballast.stiffness_scale, h2=p.rail_pad.stiffness_scale, impact_angle=p.impact_angle,
            pad_stiffness=p.rail_pad.stiffness, ballast_stiffness_per_length=p.ballast.stiffness_per_length,
            void_sleeper=first_void.sleeper if first_void else -1, record_file="", record_columns="")
        for j in range(N_VOID_GAPS):
            self._values[f"void_gap_{j + 1}"] = float(first_void.gaps[j]) if first_void else 0.0

    def _add_model_parameters(self) -> None:
        """The parameters that change the track model: speed, loads, stiffness scales, voids, ..."""
        self.add_parameter("speed", "vehicle speed along increasing x, to extrapolate wheel_x over a "
                           "step and to start the static state", "m/s", *self._accessors("speed"))
        self.add_parameter("static_wheel_load", "static load of each wheel (axle_load / 2), positive; the "
                           "track starts in static equilibrium under it", "N",
                           *self._accessors("static_wheel_load"))
        self.add_parameter("h1", "ballast stiffness scale (track.ballast.stiffness_scale)", "-",
                           *self._accessors("h1"))
        self.add_parameter("h2", "rail-pad stiffness scale (track.rail_pad.stiffness_scale)", "-",
                           *self._accessors("h2"))
        self.add_parameter("impact_angle", "crossing impact (dip) angle (track.crossing.impact_angle)",
                           "rad", *self._accessors("impact_angle"))
        self.add_parameter("pad_stiffness", "rail-pad stiffness per rail seat (track.rail_pad.stiffness)",
                           "N/m", *self._accessors("pad_stiffness"))
        self.add_parameter("ballast_stiffness_per_length", "ballast bed stiffness per metre of sleeper, "
                           "N/m per m (track.ballast.stiffness_per_length)", "N/m2",
                           *self._accessors("ballast_stiffness_per_length"))
        self._add_integer("void_sleeper", "sleeper index whose ballast void is added or replaced by "
                          "void_gap_1..6; -1: the baked voids unchanged")
        for j in range(N_VOID_GAPS):
            self.add_parameter(f"void_gap_{j + 1}", f"ballast void gap at point {j + 1} of 6, equidistant "
                               "from sleeper end to end (used when void_sleeper >= 0)", "m",
                               *self._accessors(f"void_gap_{j + 1}"))

    def _add_run_parameters(self) -> None:
        """How the FMU is coupled and what it records: extrapolation, offset, record settings."""
        self.add_parameter("extrapolate", "true: inputs are start-of-step values, extrapolated with vz and "
                           "speed (Jacobi hosts); false: end-of-step values (Gauss-Seidel, vehicle first)",
                           "-", *self._accessors("extrapolate", bool), boolean=True)
        self.add_parameter("extrapolate_force", "true: wheel{i}_Fz_coupling is the contact force "
                           "extrapolated to the middle of the next step (second-order coupling for a "
                           "vehicle that holds its input); false: equal to wheel{i}_Fz", "-",
                           *self._accessors("extrapolate_force", bool), boolean=True)
        self.add_parameter("auto_offset", "keep the difference between the vehicle's first wheel_z and the "
                           "track's static wheel position as an offset (no drop transient)", "-",
                           *self._accessors("auto_offset", bool), boolean=True)
        self._add_integer("record_every", "record the track state every this many steps (0: never)")
        self._register(String("record_file", causality=Fmi2Causality.parameter,
                              variability=Fmi2Variability.tunable,
                              description=self._describe("if not empty: at terminate the recorded states "
                                                         "(t, q, v, a, x, Fz, parts) are written to this .npz",
                                                         "-"),
                              getter=lambda: self._values["record_file"],
                              setter=lambda value: self._values.__setitem__("record_file", str(value))), "-")
        self._register(String("record_columns", causality=Fmi2Causality.parameter,
                              variability=Fmi2Variability.fixed,
                              description=self._describe(
                                  "what to record of the states: empty for every column of q, v and a; "
                                  'else JSON {"q": [i, ...], "v": [...], "a": [...]} with the columns '
                                  "(0-based) of each field to record, a field left out is not recorded",
                                  "-"),
                              getter=lambda: self._values["record_columns"],
                              setter=self._accessors("record_columns", str)[1]), "-")

    def _add_wheel_ports(self) -> None:
        """Per wheel: the inputs x, z, vz and the outputs Fz, Fz_coupling, Fz_rail, Fz_nose, rail_z."""
        for i in range(self._n):
            label = self._label(i)
            self.add_input(f"wheel{i + 1}_x", f"track coordinate of wheel {i + 1} ({label})", "m",
                           *self._input(self._x, i))
            self.add_input(f"wheel{i + 1}_z", f"vertical position of wheel {i + 1} ({label}) contact "
                           "point, upward +", "m", *self._input(self._z, i))
            self.add_input(f"wheel{i + 1}_vz", f"vertical velocity of wheel {i + 1} ({label}), upward +",
                           "m/s", *self._input(self._vz, i))
        for i in range(self._n):
            label = self._label(i)
            self._add_output_with_start(
                f"wheel{i + 1}_Fz", f"vertical contact force on wheel {i + 1} ({label}), upward +; "
                "static_wheel_load until the first step", "N", lambda i=i: self._output("Fz", i),
                ("static_wheel_load",))
            self._add_output_with_start(
                f"wheel{i + 1}_Fz_coupling", f"vertical contact force for the input of wheel {i + 1} "
                f"({label}): wheel{i + 1}_Fz, extrapolated to the middle of the next communication step "
                "when extrapolate_force; connect it to the vehicle", "N",
                lambda i=i: self._output("coupling", i), ("static_wheel_load",))
            self.add_output(f"wheel{i + 1}_Fz_rail", f"contact force of wheel {i + 1} ({label}) on the "
                            "running or wing rail", "N", lambda i=i: self._output("rail", i),
                            ("static_wheel_load",))
            self.add_output(f"wheel{i + 1}_Fz_nose", f"contact force of wheel {i + 1} ({label}) on the "
                            "crossing nose", "N", lambda i=i: self._output("nose", i))
            self.add_output(f"wheel{i + 1}_rail_z", f"rail deflection under wheel {i + 1} ({label}), "
                            "upward +; 0 until the first step", "m", lambda i=i: self._output("rail_z", i))

    def _add_counter_outputs(self) -> None:
        """The integrator's work counters (:data:`COUNTER_OUTPUTS`, Integer) and the wall times of the
        static equilibrium and of the step-matrix factorization (Real, [s]); 0 until the first step."""
        for name, (attr, text) in COUNTER_OUTPUTS.items():
            self._register(Integer(name, causality=Fmi2Causality.output, variability=Fmi2Variability.discrete,
                                   description=self._describe(f"{text} so far (monitoring)", "-"),
                                   getter=lambda attr=attr: int(getattr(self._counters(), attr))), "-")
            self._initial_dependencies[name] = ()
        self._add_python_steps_output()
        for name, text in (("wall_statics", "static equilibrium under the wheels at the first step"),
                           ("wall_factor", "set-up of the time integrator (LU of the step matrix)")):
            self._register(Real(name, causality=Fmi2Causality.output, variability=Fmi2Variability.discrete,
                                description=self._describe(f"wall time of the {text} (monitoring)", "s"),
                                getter=lambda name=name: float(getattr(self._cosim, name, 0.0))), "s")
            self._initial_dependencies[name] = ()

    def _counters(self) -> "_dynamics.Counters":
        c = self._cosim
        return c.counters if c is not None else _dynamics.Counters()

    # ------------------------------------------------------------- registration
    def _add_integer(self, name: str, description: str) -> None:
        """A fixed Integer parameter (the base class registers Real and Boolean ones)."""
        self._register(Integer(name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed,
                               description=self._describe(description, "-"),
                               getter=lambda: self._values[name],
                               setter=self._accessors(name, int)[1]), "-")

    def _add_output_with_start(self, name: str, description: str, unit: str, getter, depends_on) -> None:
        """A continuous Real output with initial="approx", so it carries a start value
        (the getter's value at build time) and stays an InitialUnknown."""
        self._register(Real(name, causality=Fmi2Causality.output, variability=Fmi2Variability.continuous,
                            initial=Fmi2Initial.approx, description=self._describe(description, unit),
                            getter=getter), unit)
        self._initial_dependencies[name] = tuple(depends_on)

    def _add_sensor_outputs(self) -> None:
        """One output per baked sensor, then ``<id>_acc`` per displacement sensor (SensorReader's order)."""
        names = {v.name for v in self.vars.values()}
        outputs = [(s.id, s, SENSOR_UNITS[s.type]) for s in self._sensors]
        outputs += [(s.id + ACCELEROMETER_SUFFIX, s, "m/s2") for s in self._sensors if s.type == "displacement"]
        self._sensor_names = [name for name, _, _ in outputs]
        for j, (name, s, unit) in enumerate(outputs):
            if name in names:
                raise ValueError(f"sensor output {name!r} clashes with another variable of the track FMU")
            names.add(name)
            self.add_output(name, self._sensor_description(s, unit), unit, lambda j=j: self._sensor_output(j))

    @staticmethod
    def _sensor_description(s: "_sensors.Sensor", unit: str) -> str:
        coord = "y" if s.body.startswith("sleeper_") else "x"   # Sensor.coord: y on sleepers, x on rails
        where = f"on {s.body} at {coord} = {s.coord:.4f} m"
        if s.type == "pressure":
            text = f"sleeper-ballast contact pressure under {s.body} at y = {s.coord:.4f} m, compressive +"
        elif s.type == "strain":
            text = (f"longitudinal strain of a {s.gauge_length:g} m gauge {where}, {s.z:g} m above the "
                    "neutral axis, tensile +")
        elif s.type == "acceleration":
            text = f"vertical acceleration {where}, upward +"
        elif unit == "m":
            text = (f"vertical displacement {where}, upward +; the displacement itself: the measurement's "
                    f"reconstruction from the accelerometer ({s.id}{ACCELEROMETER_SUFFIX}, a zero-phase "
                    "high-pass) is not causal and is applied offline")
        else:
            text = (f"vertical acceleration of the accelerometer of displacement sensor {s.id} {where}, "
                    "upward +; reconstruct the displacement from it offline as for the measurement")
        return f"sensor {s.id} (group {s.group}, {s.type}): {text}; 0 until the first step"

    def _sensor_output(self, j: int) -> float:
        c = self._cosim
        if c is None or c.integ is None:
            return 0.0
        if self._sensor_values is None:   # first read since the state changed
            i = c.integ
            self._sensor_values = self._reader.read(i.q, i.v, i.a)
        return float(self._sensor_values[j])

    @staticmethod
    def _label(i: int) -> str:
        return f"wheelset {i // 2 + 1} {SIDE[i % 2]}"

    def _accessors(self, name: str, cast=float):
        def get():
            return self._values[name]

        def set_(value):
            if self._model is not None and not self._restoring:
                self.log_warning(f"parameter {name} is fixed after initialization: new value {value!r} ignored")
                return
            self._values[name] = cast(value)
        return get, set_

    @staticmethod
    def _input(array: np.ndarray, i: int):
        def set_(value):
            array[i] = value
        return (lambda: float(array[i])), set_

    def get_real(self, vrs):
        """The Real variables ``vrs``; a read of wheel outputs only (what a master reads every step)
        takes them from one vector, the same values as their getters (:meth:`_output`) give."""
        key = tuple(vrs)
        slots = self._bulk.get(key, False)
        if slots is False:
            slots = (np.array([self._wheel_slot[vr] for vr in key], np.intp)
                     if key and all(vr in self._wheel_slot for vr in key) else None)
            if len(self._bulk) < 8:
                self._bulk[key] = slots
        c = self._cosim
        if slots is None or c is None:
            return super().get_real(vrs)
        values = np.concatenate([c.Fz, c.Fz_coupling, c.parts[:, 0], c.parts[:, 1], c.rail_w])
        return values[slots].tolist()

    def _output(self, which: str, i: int) -> float:
        c = self._cosim
        if c is None:  # before the first step: the static state's contact forces
            if which in ("Fz", "rail", "coupling"):
                return float(self._values["static_wheel_load"])
            return 0.0
        if which == "Fz":
            return float(c.Fz[i])
        if which == "coupling":
            return float(c.Fz_coupling[i])
        if which == "rail":
            return float(c.parts[i, 0])
        if which == "nose":
            return float(c.parts[i, 1])
        return float(c.rail_w[i])

    # ---------------------------------------------------------------- parameters
    def _check_values(self) -> None:
        """Raise ValueError naming the first invalid parameter value."""
        v = self._values
        positive = ("static_wheel_load", "h1", "h2", "pad_stiffness", "ballast_stiffness_per_length")
        for name in ("speed", "impact_angle") + positive + tuple(f"void_gap_{j + 1}" for j in range(N_VOID_GAPS)):
            if not math.isfinite(v[name]):
                raise ValueError(f"parameter {name} = {v[name]!r} is not finite")
        for name in positive:
            if not v[name] > 0.0:
                raise ValueError(f"parameter {name} = {v[name]!r} must be > 0")
        for name in ("speed", "impact_angle") + tuple(f"void_gap_{j + 1}" for j in range(N_VOID_GAPS)):
            if v[name] < 0.0:
                raise ValueError(f"parameter {name} = {v[name]!r} must be >= 0")
        n_sleepers = self._baked.layout.sleepers
        if not -1 <= v["void_sleeper"] < n_sleepers:
            raise ValueError(f"parameter void_sleeper = {v['void_sleeper']} must be -1 (none) or a sleeper "
                             f"index 0..{n_sleepers - 1}")
        if v["record_every"] < 0:
            raise ValueError(f"parameter record_every = {v['record_every']} must be >= 0")
        self._record_columns()

    def _record_columns(self) -> dict | None:
        """The parameter ``record_columns`` parsed: None (all of q, v, a) or field -> column indices.

        Raises
        ------
        ValueError
            Not a JSON object of lists of integers with keys among q, v, a.
        """
        text = self._values["record_columns"].strip()
        if not text:
            return None
        try:
            spec = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ValueError(f"parameter record_columns is not JSON: {exc}") from None
        if not isinstance(spec, dict) or not set(spec) <= set(_cosim.STATE_FIELDS) or not all(
                isinstance(c, list) and all(isinstance(i, int) and not isinstance(i, bool) for i in c)
                for c in spec.values()):
            raise ValueError(f"parameter record_columns = {text[:60]!r}: expected a JSON object with keys among "
                             f"{list(_cosim.STATE_FIELDS)}, each a list of column indices (integers)")
        return spec

    def track_params(self) -> "_params.TrackParams":
        """The baked track parameters with the FMU parameters applied."""
        v, p = self._values, self._baked
        voids = p.ballast.voids
        k = v["void_sleeper"]
        if k >= 0:
            gaps = tuple(float(v[f"void_gap_{j + 1}"]) for j in range(N_VOID_GAPS))
            voids = tuple(sorted([s for s in voids if s.sleeper != k] + [_params.VoidSpec(k, gaps)],
                                 key=lambda s: s.sleeper))
        return dataclasses.replace(
            p, impact_angle=v["impact_angle"],
            rail_pad=dataclasses.replace(p.rail_pad, stiffness=v["pad_stiffness"], stiffness_scale=v["h2"]),
            ballast=dataclasses.replace(p.ballast, stiffness_per_length=v["ballast_stiffness_per_length"],
                                        stiffness_scale=v["h1"], voids=voids))

    def _build_model(self) -> None:
        params = self.track_params()
        if self._model is None or params != self._built:
            # the FMU is an edge: it, not track/, chooses the solid's disk cache (from the host's environment)
            self._model = _model.build_track(params, cache_dir=_cache.cache_dir_from_env(os.environ))
            self._built = params
            self._reader = SensorReader(self._model, self._sensors) if self._sensors else None
        self._sensor_values = None

    def _new_cosim(self, h: float) -> "_cosim.TrackCosim":
        """The TrackCosim of step ``h`` [s]; its record sized for the host's stop time when it gave one."""
        v = self._values
        c = _cosim.TrackCosim(self._built, self._n, v["static_wheel_load"], h, speed=v["speed"],
                              extrapolate=v["extrapolate"], auto_offset=v["auto_offset"],
                              record_every=v["record_every"], model=self._model,
                              extrapolate_force=v["extrapolate_force"], record_columns=self._record_columns())
        self._cosim_columns = v["record_columns"]   # what the record holds (_same_settings)
        if v["record_every"] and self.stop_time is not None and self.stop_time > self.start_time:
            steps = int(math.floor((self.stop_time - self.start_time) / h * (1.0 + STEP_RTOL)))
            c.record.reserve(steps // v["record_every"] + 1)
        return c

    def setup_experiment(self, start_time: float, stop_time=None, tolerance=None):
        super().setup_experiment(start_time, stop_time, tolerance)
        self.stop_time = None if stop_time is None else float(stop_time)

    # ----------------------------------------------------------------- lifecycle
    def initialize_model(self) -> None:
        self._check_values()
        self._build_model()
        self._cosim = None
        self._t_first = None
        self._python_steps = 0
        if self._model is not None:
            spec = self._record_columns() or {}
            bad = [k for k, cols in spec.items() if any(not 0 <= i < self._model.n for i in cols)]
            if bad:
                raise ValueError(f"parameter record_columns: columns of {bad[0]} must lie in 0..{self._model.n - 1}")
        if self._values["record_file"] and not self._values["record_every"]:
            self.log_warning("record_file is set but record_every = 0: nothing will be recorded")

    def _check_on_panel(self) -> None:
        """Raise ValueError if a wheel's input x lies outside the modelled panel."""
        sleepers = self._model.layout.sleepers
        lo, hi = sleepers[0].x, sleepers[-1].x
        if lo <= self._x.min() and self._x.max() <= hi:   # the common case, without temporaries
            return
        outside = np.flatnonzero(~((self._x >= lo) & (self._x <= hi)))
        if outside.size:
            i = int(outside[0])
            raise ValueError(f"wheel{i + 1}_x = {self._x[i]:.4f} m is outside the modelled panel "
                             f"[{lo:.4f}, {hi:.4f}] m (first to last sleeper); place the vehicle on it "
                             "(e.g. the vehicle FMU's parameter x0)")

    def advance(self, current_time: float, step_size: float) -> None:
        self._check_on_panel()
        c = self._cosim
        if c is None:
            c = self._new_cosim(step_size)
            self._cosim, self._t_first = c, current_time
        elif abs(step_size - c.h) > STEP_RTOL * c.h:
            raise StepSizeError(f"the track FMU runs with a fixed communication step: step size "
                                f"{step_size!r} s differs from the first step {c.h!r} s")
        self._sensor_values = None   # stale from here on, whatever the step's outcome
        try:  # a ConvergenceError leaves the state unchanged: the step may be retried
            c.do_step(self._x, self._z, self._vz)
        except _cosim.DivergenceError as exc:
            # the step has overwritten the state with a diverged one: refuse to go on
            self._failure = f"{exc} (restore an FMU state saved before to continue)"
            raise
        self._stepped_in_python()

    # ----------------------------------------------------------------- fast path (fmus.fast)
    def _register_fast(self) -> None:
        """Register the compiled C step with the FMU's shim (fmus.fast), where there is one and the
        TrackCosim can be stepped outside Python (track.fused.fused_unavailable); else step in Python."""
        self._fast = False
        lib = shim_library(self.resources) if fast_enabled() else None
        if lib is None or _fused.fused_unavailable(self._cosim, extrapolated_inputs=True) is not None:
            return
        import importlib
        cfunc = importlib.import_module(_unit_step.__name__.rsplit(".", 1)[0] + ".unit_cfunc")  # compiles / loads
        self._pack = cfunc.pack
        self._ctx = np.ones(cfunc.SLOT * len(cfunc.SPEC), np.int64)
        vr = {v.name: v.value_reference for v in self.vars.values()}
        n = self._n
        ins = [vr[f"wheel{i + 1}_{k}"] for k in ("x", "z", "vz") for i in range(n)]
        outs = [0] * (len(WHEEL_OUTPUTS) * n)
        for ref, slot in self._wheel_slot.items():
            outs[slot] = ref
        n_wheel = len(outs)
        outs += [vr[name] for name in self._sensor_names]     # evaluated when read (cfunc.unit_sensors_c)
        fast = FastPath(lib, cfunc.unit_step_address(), ins, self._inp, outs, np.zeros(len(outs)),
                        self._fast_load, self._fast_sync, lazy=cfunc.unit_sensors_address(), n_eager=n_wheel)
        if fast.register(self._ctx.ctypes.data):
            self._fast = fast

    def _fast_load(self, current: bool) -> bool:
        """The shim's ``load``: the compiled step's buffers current (see fmus.fast.FastPath)."""
        c = self._cosim
        if (self._failure is not None or c is None or not c.initialized
                or _fused.fused_unavailable(c, extrapolated_inputs=True) is not None):
            return False
        u = self._unit
        if current and u is not None:
            return True
        if u is None or u.engine is not c:
            sleepers = self._model.layout.sleepers
            sensors = self._reader.arrays if self._reader is not None else _unit_step.NO_SENSORS
            u = self._unit = _unit_step.UnitSteps(c, self._inp, sleepers[0].x, sleepers[-1].x, STEP_RTOL, sensors)
            u.outbuf = self._fast.out_buf
            self._ctx_record = None
        u.read_engine()
        if self._ctx_record is not c.record._args:   # the record's arrays moved (or a new unit)
            self._pack(u.arguments(), self._ctx)
            self._ctx_record = c.record._args
        return True

    def _fast_sync(self) -> None:
        """The shim's ``sync``: the compiled steps' state into the TrackCosim."""
        if self._unit is not None and self._unit.engine is self._cosim and self._unit.write_engine():
            self._sensor_values = None

    def terminate(self):
        path = self._values["record_file"]
        if not path:
            return
        try:
            self.write_record(path)
        except Exception as exc:  # never raise into pythonfmu (it would free the instance)
            self.log_error(f"record_file {path!r} could not be written: {type(exc).__name__}: {exc}")

    def write_record(self, path: str | Path) -> Path:
        """Write the recorded states as ``.npz`` (uncompressed, straight from the record's arrays).

        Arrays: ``t`` (nt,) simulation time [s]; ``q``, ``v``, ``a`` reduced coordinates [m, rad],
        their rates and accelerations, (nt, n_dofs) or, with ``record_columns``, (nt, k) for the
        fields asked for, each with ``<field>_columns`` (k,) its columns
        (``track.cosim.state_rows`` restores full rows); ``x`` (nt, n_wheels) [m], ``Fz``
        (nt, n_wheels) [N], ``parts`` (nt, n_wheels, 2) [N] (rail / wing rail, nose); and
        ``track_params`` (the effective parameters as UTF-8 JSON bytes, for
        ``track.params.track_params_from_dict``), ``static_wheel_load`` [N], ``h`` [s].  With no
        step taken the arrays are empty.
        """
        path = Path(path)
        if self._cosim is not None:
            arrays = self._cosim.record.arrays()   # views: np.savez writes them in chunks, no copy
            arrays["t"] = arrays["t"] + self._t_first
            h = self._cosim.h
        else:
            n_dofs = self._model.n if self._model is not None else 0
            arrays = _cosim.Record(n_dofs, self._n, self._record_columns()).arrays()
            h = float("nan")
        params = self._built if self._built is not None else self.track_params()
        params_json = json.dumps(dataclasses.asdict(params)).encode("utf-8")  # bytes: HDF5-friendly
        np.savez(path, **arrays, track_params=np.array(params_json),
                 static_wheel_load=np.array(self._values["static_wheel_load"]), h=np.array(h))
        return path if path.suffix == ".npz" else path.with_name(path.name + ".npz")

    # ----------------------------------------------------------------- FMU state
    def get_internal_state(self) -> Dict[str, Any]:
        state = super().get_internal_state()
        c = self._cosim
        state.update(initialized=self._model is not None, t_first=self._t_first,
                     h=None if c is None else c.h, cosim=None if c is None else c.get_state())
        return state

    def set_internal_state(self, state: Dict[str, Any]) -> None:
        super().set_internal_state(state)
        self._t_first = state["t_first"]
        self._sensor_values = None
        if not state["initialized"]:
            self._model = self._built = self._cosim = None
            return
        self._build_model()  # no-op unless the restored parameters differ from the built ones
        if state["cosim"] is None:
            self._cosim = None
            return
        c = self._cosim
        if c is None or c.model is not self._model or not self._same_settings(c, state["h"]):
            c = self._cosim = self._new_cosim(state["h"])
        c.set_state(state["cosim"])

    def _same_settings(self, c: "_cosim.TrackCosim", h: float) -> bool:
        v = self._values
        return (c.h == h and c.speed == v["speed"] and c.extrapolate == v["extrapolate"]
                and c.extrapolate_force == v["extrapolate_force"]
                and c.auto_offset == v["auto_offset"] and c.record_every == v["record_every"]
                and self._cosim_columns == v["record_columns"]
                and np.all(c.Q0 == v["static_wheel_load"]))
