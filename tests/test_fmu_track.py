"""Track FMU standalone in FMPy: validation, statics against the track's own static
stiffness, parameters, FMU state, errors, recording, coupling with the bogie FMU, and
the sensor outputs (one per sensor of the scenario's layout) against track.sensors."""
from __future__ import annotations

import dataclasses
import json
import logging
import sys

import numpy as np
import pytest

fmpy = pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

from fmpy import calloc, extract, free, read_model_description  # noqa: E402
from fmpy.fmi1 import FMICallException  # noqa: E402
from fmpy.fmi2 import (  # noqa: E402
    FMU2Slave,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
)
from fmpy.validation import validate_fmu  # noqa: E402
from scipy.optimize import brentq  # noqa: E402

from fmus.build import build_fmu, build_track_fmu  # noqa: E402
from track.contact import HERTZ_CONSTANT, hertz_deflection  # noqa: E402
from track.model import build_track  # noqa: E402
from track.params import (  # noqa: E402
    BallastParams,
    LayoutParams,
    PadOverride,
    RailPadParams,
    TrackParams,
    VoidSpec,
    track_params_from_dict,
)
from track.statics import static_equilibrium  # noqa: E402

FMI_DISCARD = 2
FMI_ERROR = 3           # status of the log messages that explain a discard
PARAMS = TrackParams(layout=LayoutParams(type="plain", sleepers=16))  # small plain track: fast
Q0 = 98100.0            # N: static wheel load (20 t axle)
X_MID = 4.5             # m: midspan between sleepers 7 and 8 (0.6 m spacing, sleeper 0 at x = 0)
D_PUSH = 0.2e-3         # m: the held wheel is pushed this far below its static position
H = 1e-4                # s: communication step
N_SETTLE = 2000         # steps (0.2 s): the slowest track mode on the Hertz spring has decayed
DF_FLEX = 5e3           # N: load step of the central difference for the static flexibility
SIDES = ("left", "right")  # wheel 1, wheel 2


@pytest.fixture(scope="module")
def fmu_files(tmp_path_factory):
    """Track FMUs (2 and 4 wheels, plain track) and the bogie FMU, built once per module."""
    out = tmp_path_factory.mktemp("track_fmus")
    paths = {"track2": build_track_fmu(PARAMS, 2, out, name="track2", speed=0.0, extrapolate=False,
                                       auto_offset=False),
             "track4": build_track_fmu(PARAMS, 4, out, name="track4", speed=5.0, extrapolate=False),
             "bogie": build_fmu("bogie", out)}
    return {kind: (path, extract(str(path), unzipdir=str(out / f"{kind}_x"))) for kind, path in paths.items()}


class Instance:
    """An FMU2Slave with name lookup, typed parameter setting and captured log messages."""

    def __init__(self, fmu_files, kind: str, name: str | None = None):
        path, unzipdir = fmu_files[kind]
        self.md = read_model_description(str(path))
        self.var = {v.name: v for v in self.md.modelVariables}
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.n = sum(1 for v in self.md.modelVariables if v.name.endswith("_z") and v.name.startswith("wheel")
                     and not v.name.endswith("rail_z"))
        self.messages: list[tuple[int, str]] = []
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=unzipdir,
                             modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=name or kind)
        self._callbacks = fmi2CallbackFunctions()   # kept alive as long as the instance
        self._callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        self._callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self._callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        self.fmu.instantiate(callbacks=self._callbacks, loggingOn=True)
        self.closed = False

    def _log(self, component, instance, status, category, message):
        self.messages.append((status, message.decode()))

    def set_parameters(self, **values):
        for name, value in values.items():
            kind = self.var[name].type
            if kind == "Boolean":
                self.fmu.setBoolean([self.vr[name]], [bool(value)])
            elif kind == "Integer":
                self.fmu.setInteger([self.vr[name]], [int(value)])
            elif kind == "String":
                self.fmu.setString([self.vr[name]], [str(value)])
            else:
                self.fmu.setReal([self.vr[name]], [float(value)])

    def init(self, **parameters):
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        self.set_parameters(**parameters)
        self.fmu.exitInitializationMode()
        return self

    def set(self, port, values):
        self.fmu.setReal([self.vr[f"wheel{i + 1}_{port}"] for i in range(self.n)], [float(v) for v in values])

    def get(self, port):
        return np.array(self.fmu.getReal([self.vr[f"wheel{i + 1}_{port}"] for i in range(self.n)]))

    def outputs(self):
        return np.concatenate([self.get(p) for p in ("Fz", "Fz_rail", "Fz_nose", "rail_z")])

    def errors(self):
        return [m for s, m in self.messages if s == FMI_ERROR]

    def close(self):
        if not self.closed:
            self.fmu.terminate()
            self.fmu.freeInstance()
            self.closed = True


@pytest.fixture
def instances(fmu_files):
    made = []

    def make(kind, name=None):
        inst = Instance(fmu_files, kind, name)
        made.append(inst)
        return inst
    yield make
    for inst in made:
        inst.close()


def static_prediction(params: TrackParams, x: float, d: float, Q: float) -> dict:
    """Static force on two wheels (left, right at ``x``) held ``d`` below their static position.

    Independent of the FMU: the static position is ``z_s = w(Q) - delta_H(Q)`` (rail
    top at 0, deflection under the static loads incl. the point's residual
    flexibility, Hertz compression), the track's static flexibility ``f`` at the
    point comes from two static solutions at ``Q +- DF_FLEX`` on both wheels (the
    symmetric load case the wheels apply), and the force solves
    ``F = C_H (delta_H(Q) + d - f (F - Q))^1.5``.
    """
    model = build_track(params)
    points = [model.rail_point(side, x) for side in ("left", "right")]

    def solve(F):
        st = static_equilibrium(model, [(p, -F) for p in points])
        return np.array([p.value(st.q, -F) for p in points]), st

    w0, st0 = solve(Q)
    w_plus, st_plus = solve(Q + DF_FLEX)
    w_minus, st_minus = solve(Q - DF_FLEX)
    f = -(w_plus[0] - w_minus[0]) / (2 * DF_FLEX)   # m/N
    delta0 = hertz_deflection(Q)
    F = brentq(lambda F: F - HERTZ_CONSTANT * max(delta0 + d - f * (F - Q), 0.0) ** 1.5, Q, Q + d / f,
               xtol=1e-9, rtol=1e-15)
    return {"z_static": w0 - delta0, "F": F, "w": w0[0] - f * (F - Q), "flexibility": f,
            "same_contact_set": bool(np.array_equal(st_plus.active, st_minus.active)
                                     and np.array_equal(st0.active, st_plus.active))}


# ------------------------------------------------------------------------ description
@pytest.mark.parametrize("kind", ("track2", "track4"))
def test_fmpy_validation_reports_no_problems(fmu_files, kind):
    assert validate_fmu(str(fmu_files[kind][0])) == []


def test_model_description_ports_units_and_baked_defaults(fmu_files, tmp_path):
    md = read_model_description(str(fmu_files["track2"][0]))
    by_name = {v.name: v for v in md.modelVariables}
    assert md.coSimulation.canGetAndSetFMUstate and md.coSimulation.canSerializeFMUstate
    for i in (1, 2):
        for port, unit in (("x", "m"), ("z", "m"), ("vz", "m/s")):
            v = by_name[f"wheel{i}_{port}"]
            assert v.causality == "input" and v.unit == unit and v.description.endswith(f"[{unit}]")
        for port, unit in (("Fz", "N"), ("Fz_rail", "N"), ("Fz_nose", "N"), ("rail_z", "m")):
            v = by_name[f"wheel{i}_{port}"]
            assert v.causality == "output" and v.unit == unit and v.description.endswith(f"[{unit}]")
        assert by_name[f"wheel{i}_Fz"].initial == "approx" and float(by_name[f"wheel{i}_Fz"].start) == Q0
    assert "wheel3_x" not in by_name
    assert all(v.description.rstrip().endswith("]") for v in md.modelVariables)
    fixed = ("speed", "static_wheel_load", "h1", "h2", "impact_angle", "pad_stiffness",
             "ballast_stiffness_per_length", "void_sleeper", "extrapolate", "auto_offset", "record_every")
    assert all(by_name[p].causality == "parameter" and by_name[p].variability == "fixed" for p in fixed)
    assert by_name["record_file"].variability == "tunable" and by_name["record_file"].type == "String"
    assert by_name["void_sleeper"].type == "Integer" and by_name["extrapolate"].type == "Boolean"
    assert by_name["ballast_stiffness_per_length"].unit == "N/m2"
    assert all(u.dependencies == [] for u in md.outputs)          # no direct feed-through
    initial = {u.variable.name: [d.name for d in u.dependencies] for u in md.initialUnknowns}
    assert initial["wheel1_Fz"] == ["static_wheel_load"] and initial["wheel2_rail_z"] == []

    # parameter start values are the baked scenario's values (here with a void and a pad scale)
    baked = dataclasses.replace(
        PARAMS, impact_angle=0.012,
        rail_pad=RailPadParams(stiffness=2.0e8, stiffness_scale=1.5, overrides=(PadOverride(3, 2.0),)),
        ballast=BallastParams(stiffness_scale=0.7, voids=(VoidSpec(5, (0.0, 1e-4, 2e-4, 3e-4, 4e-4, 5e-4)),)))
    md2 = read_model_description(str(build_track_fmu(baked, 2, tmp_path, speed=27.5, static_wheel_load=9e4)))
    start = {v.name: v.start for v in md2.modelVariables}
    assert {k: float(start[k]) for k in ("speed", "static_wheel_load", "h1", "h2", "impact_angle",
                                         "pad_stiffness", "wheel1_Fz")} == \
        {"speed": 27.5, "static_wheel_load": 9e4, "h1": 0.7, "h2": 1.5, "impact_angle": 0.012,
         "pad_stiffness": 2.0e8, "wheel1_Fz": 9e4}
    assert int(start["void_sleeper"]) == 5
    assert [float(start[f"void_gap_{j}"]) for j in range(1, 7)] == [0.0, 1e-4, 2e-4, 3e-4, 4e-4, 5e-4]


def test_track_params_round_trip_through_json():
    p = TrackParams(rail_pad=RailPadParams(overrides=(PadOverride(17, 3.0),)),
                    ballast=BallastParams(voids=(VoidSpec(21, (0.0, 4e-4, 9e-4, 9e-4, 4e-4, 0.0)),)))
    assert track_params_from_dict(json.loads(json.dumps(dataclasses.asdict(p)))) == p


# ----------------------------------------------------------------------------- statics
def run_held(inst, z, n_steps=N_SETTLE):
    """Hold both wheels at (X_MID, z), vz = 0; returns the history of wheel1_Fz."""
    inst.set("x", [X_MID] * 2)
    inst.set("z", z)
    inst.set("vz", [0.0, 0.0])
    F = np.empty(n_steps)
    for k in range(n_steps):
        inst.fmu.doStep(k * H, H)
        F[k] = inst.get("Fz")[0]
    return F


def test_held_wheel_settles_to_static_stiffness_and_h2_is_a_parameter(instances):
    """Both wheels held 0.2 mm below their static position at midspan: once the
    transient has decayed, the contact force is the static one of the track's static
    flexibility and the Hertz law.  The same FMU with h2 = 1 and h2 = 3 (no rebuild)
    gives two different forces, each matching its own prediction.

    Tolerance: the ballast contact set is the same at Q +- 5 kN (asserted), so the
    static response is linear over the range and the prediction is exact up to
    round-off; what is left is the undecayed transient, bounded by the force's
    variation over the last 100 steps (10 ms, longer than the period of the
    slowest mode involved), which must itself be below 1e-3 relative (stationary)."""
    forces = {}
    for h2 in (1.0, 3.0):
        params = dataclasses.replace(PARAMS, rail_pad=dataclasses.replace(PARAMS.rail_pad, stiffness_scale=h2))
        pred = static_prediction(params, X_MID, D_PUSH, Q0)
        assert pred["same_contact_set"]
        inst = instances("track2", f"held_h2_{h2:g}").init(h2=h2)
        F = run_held(inst, pred["z_static"] - D_PUSH)
        wobble = np.ptp(F[-100:])
        assert wobble < 1e-3 * F[-1]
        assert abs(F[-1] - pred["F"]) <= wobble + 1e-9 * pred["F"]
        # the rail under the wheel sits at the static deflection under that force
        # (0.1 um: the transient's share, wobble times the flexibility, is below 1e-12 m)
        np.testing.assert_allclose(inst.get("rail_z"), pred["w"], rtol=0, atol=1e-10)
        # plain track: all on the running rail (the parts are Hertz forces of the last Newton
        # iterate, within the contact tolerance 1e-6 N + 1e-9 relative of the converged total)
        np.testing.assert_allclose(inst.get("Fz_rail"), inst.get("Fz"), rtol=2e-9)
        np.testing.assert_array_equal(inst.get("Fz_nose"), 0.0)
        forces[h2] = F[-1]
    # stiffer pads: stiffer track, larger force for the same push (predicted +2.2 %)
    assert forces[3.0] > 1.01 * forces[1.0]


# --------------------------------------------------------------------------- FMU state
def moving_inputs(k: int, n: int = 2):
    """Wheel inputs at step k: moving at 5 m/s with a small vertical wave (up to 20 um)."""
    t = k * H
    x = np.full(n, 3.0 + 5.0 * t)
    z = 2e-5 * np.sin(2 * np.pi * 40.0 * t + np.arange(n))
    vz = 2e-5 * 2 * np.pi * 40.0 * np.cos(2 * np.pi * 40.0 * t + np.arange(n))
    return x, z, vz


def drive(inst, k0, n):
    out = []
    for k in range(k0, k0 + n):
        x, z, vz = moving_inputs(k, inst.n)
        inst.set("x", x)
        inst.set("z", z)
        inst.set("vz", vz)
        inst.fmu.doStep(k * H, H)
        out.append(inst.outputs())
    return np.array(out)


def test_fmu_state_round_trip_is_bit_identical(instances):
    """get state, run N steps, set state, run again: identical outputs; also through
    serialisation, and deserialised into a second instance (which builds its
    TrackCosim from the state)."""
    params = dict(speed=5.0, extrapolate=True, auto_offset=True)
    inst = instances("track2", "state_a").init(**params)
    drive(inst, 0, 20)
    state = inst.fmu.getFMUstate()
    first = drive(inst, 20, 30)
    assert np.ptp(first[:, 0]) > 100.0     # the forces really vary (N)
    inst.fmu.setFMUstate(state)
    second = drive(inst, 20, 30)
    assert np.array_equal(first, second)
    blob = inst.fmu.serializeFMUstate(state)
    inst.fmu.setFMUstate(inst.fmu.deSerializeFMUstate(blob))
    third = drive(inst, 20, 30)
    assert np.array_equal(first, third)
    inst.fmu.freeFMUstate(state)

    other = instances("track2", "state_b").init(**params)
    other.fmu.setFMUstate(other.fmu.deSerializeFMUstate(blob))
    fourth = drive(other, 20, 30)
    assert np.array_equal(first, fourth)


@pytest.mark.parametrize("extrapolate", (False, True))
def test_compiled_steps_give_the_python_steps_numbers(instances, monkeypatch, tmp_path, extrapolate):
    """The FMU's compiled steps through its C shim (fmus.fast, track.unit_step) against the Python path
    with the same inputs (XPANEL_FMU_FAST=0): 2 wheels at 5 m/s for 0.08 s, crossing rail elements (the
    compiled step hands each to Python to load and goes on), an FMU state restored on the way (Python
    sees the compiled steps' state: the shim syncs it first), a sensor-free record of every step.
    Same kernel on the same state: outputs, record and counters equal to the last bit; the output
    python_steps shows the compiled path took all but the first step."""
    runs = {}
    # the first run warms the process-wide cache of influence rows (track.dynamics._shared_factor), whose
    # solves the counter counts: run alone, the Python path solved 68 rows more than the compiled one after it
    for j, mode in enumerate(("0", "0", "1")):
        monkeypatch.setenv("XPANEL_FMU_FAST", mode)
        inst = instances("track2", f"compiled_{j}_{extrapolate}").init(
            speed=5.0, extrapolate=extrapolate, auto_offset=True, record_every=1,
            record_file=str(tmp_path / f"record_{j}.npz"))
        first = drive(inst, 0, 500)
        state = inst.fmu.getFMUstate()
        ahead = drive(inst, 500, 150)
        inst.fmu.setFMUstate(state)
        again = drive(inst, 500, 300)
        counters = inst.fmu.getInteger([inst.vr[k] for k in ("track_steps", "linear_solves", "python_steps")])
        inst.close()
        runs[mode] = (np.vstack([first, ahead, again]), counters, np.load(tmp_path / f"record_{j}.npz"))
    (out0, c0, rec0), (out1, c1, rec1) = runs["0"], runs["1"]
    assert np.ptp(out0[:, 0]) > 100.0                 # the forces really vary (N)
    assert np.array_equal(out0, out1)
    assert c0[:2] == c1[:2]
    assert c0[2] == 950 and c1[2] == 1                # Python took every step / only the first
    assert set(rec0.files) == set(rec1.files) and rec0["t"].size == 801   # the static state and 800 steps
    for key in rec0.files:
        assert np.array_equal(rec0[key], rec1[key]), key


def test_state_of_another_instance_restored_into_a_stepping_one(instances):
    """An FMU state serialized by instance A restored into instance B that has been taking compiled steps
    since other first wheel positions (so other static offsets, part of the state): B then continues as A
    does, to the last bit (the compiled step takes the restored offsets, not the ones it started with)."""
    params = dict(speed=5.0, extrapolate=True, auto_offset=True)
    a = instances("track2", "offsets_a").init(**params)
    drive(a, 0, 30)
    blob = a.fmu.serializeFMUstate(a.fmu.getFMUstate())
    ahead = drive(a, 30, 40)
    b = instances("track2", "offsets_b").init(**params)
    for k in range(30):                       # other wheel positions: 0.4 m further on
        x, z, vz = moving_inputs(k, b.n)
        b.set("x", x + 0.4)
        b.set("z", z)
        b.set("vz", vz)
        b.fmu.doStep(k * H, H)
    assert b.fmu.getInteger([b.vr["python_steps"]])[0] == 1      # B took compiled steps
    b.fmu.setFMUstate(b.fmu.deSerializeFMUstate(blob))
    assert np.array_equal(drive(b, 30, 40), ahead)


def test_state_saved_before_the_first_step_restores_lazy_construction(instances):
    """A state taken before the first doStep (no TrackCosim yet) restores to 'not
    started': the next step initializes again and gives the same outputs."""
    inst = instances("track2", "lazy").init(speed=5.0, extrapolate=True, auto_offset=True)
    state = inst.fmu.getFMUstate()
    first = drive(inst, 0, 10)
    inst.fmu.setFMUstate(state)
    np.testing.assert_array_equal(inst.get("Fz"), Q0)          # back to the static start values
    assert np.array_equal(drive(inst, 0, 10), first)
    inst.fmu.freeFMUstate(state)


def test_reset_reinitializes_from_the_parameters(instances):
    """fmi2Reset, then a new initialization: the same parameters repeat the run
    exactly; another h2 changes it (the model is rebuilt at exitInitializationMode)."""
    inst = instances("track2", "reset").init(speed=5.0, extrapolate=True, auto_offset=True)
    first = drive(inst, 0, 20)
    inst.fmu.reset()
    inst.init(speed=5.0, extrapolate=True, auto_offset=True)
    assert np.array_equal(drive(inst, 0, 20), first)
    inst.fmu.reset()
    inst.init(speed=5.0, extrapolate=True, auto_offset=True, h2=3.0)
    assert not np.array_equal(drive(inst, 0, 20), first)


def test_wheel_on_the_crossing_nose_loads_the_nose_output(tmp_path):
    """Turnout: both wheels just behind the nominal transfer point.  The crossing-side
    wheel rests on the nose (wing rail dipped below it), the other on its running
    rail; the outputs wheel_Fz_nose / wheel_Fz_rail say so."""
    from track.layout import build_layout

    params = TrackParams()
    lay = build_layout(params.layout)
    path = build_track_fmu(params, 2, tmp_path, speed=0.0, extrapolate=False)
    files = {"turnout": (path, extract(str(path), unzipdir=str(tmp_path / "x")))}
    inst = Instance(files, "turnout").init()
    try:
        inst.set("x", [lay.x_transition + 0.3] * 2)
        for k in range(5):
            inst.fmu.doStep(k * H, H)
        on_crossing = SIDES.index(lay.crossing_side)
        other = 1 - on_crossing
        Fz, rail, nose = inst.get("Fz"), inst.get("Fz_rail"), inst.get("Fz_nose")
        assert rail[on_crossing] == 0.0 and nose[on_crossing] == pytest.approx(Fz[on_crossing], rel=2e-9)
        assert nose[other] == 0.0 and rail[other] == pytest.approx(Fz[other], rel=2e-9)
        assert np.all(np.abs(Fz / Q0 - 1.0) < 0.05)    # near the static load after 5 steps from rest
    finally:
        inst.close()


# ------------------------------------------------------------------------------ errors
def test_nan_input_is_discarded_and_the_instance_continues(instances, caplog):
    """A NaN input: fmi2Discard with a message naming the input, state kept; after
    resetting the input the run continues exactly as a run that never saw the NaN."""
    inst = instances("track2", "nan").init(speed=5.0, extrapolate=True, auto_offset=True)
    ref = instances("track2", "nan_ref").init(speed=5.0, extrapolate=True, auto_offset=True)
    drive(inst, 0, 10)
    expected = drive(ref, 0, 20)
    before = inst.outputs()
    inst.fmu.setReal([inst.vr["wheel2_z"]], [float("nan")])
    with caplog.at_level(logging.ERROR), pytest.raises(FMICallException) as err:
        inst.fmu.doStep(10 * H, H)
    assert err.value.status == FMI_DISCARD
    assert np.array_equal(inst.outputs(), before)
    assert "wheel2_z" in inst.errors()[-1] and "non-finite" in inst.errors()[-1]
    assert any("wheel2_z" in r.getMessage() for r in caplog.records)
    assert np.array_equal(drive(inst, 10, 10), expected[10:])


def test_step_size_change_is_discarded(instances):
    inst = instances("track2", "step").init(speed=5.0, extrapolate=True)
    drive(inst, 0, 3)
    before = inst.outputs()
    with pytest.raises(FMICallException) as err:
        inst.fmu.doStep(3 * H, 2 * H)
    assert err.value.status == FMI_DISCARD
    assert "fixed communication step" in inst.errors()[-1]
    assert np.array_equal(inst.outputs(), before)
    inst.fmu.doStep(3 * H, H)          # the original step still works
    # libcosim hands over h(1 + 1e-12) from its integer-nanosecond clock: that is the same step
    inst.fmu.doStep(4 * H, H * (1 + 1e-12))


def test_divergence_is_discarded_until_a_state_is_restored(instances):
    """A wheel 20 mm inside the rail: the contact force exceeds 50 static loads, the
    step is discarded (DivergenceError), so is every later one, until a state saved
    before is restored."""
    inst = instances("track2", "diverge").init()
    z_static = static_prediction(PARAMS, X_MID, D_PUSH, Q0)["z_static"]
    run_held(inst, z_static, n_steps=5)
    state = inst.fmu.getFMUstate()
    inst.set("z", z_static - 0.02)
    with pytest.raises(FMICallException) as err:
        inst.fmu.doStep(5 * H, H)
    assert err.value.status == FMI_DISCARD
    assert "diverged" in inst.errors()[-1]
    inst.set("z", z_static)
    with pytest.raises(FMICallException):
        inst.fmu.doStep(5 * H, H)
    inst.fmu.setFMUstate(state)
    inst.fmu.doStep(5 * H, H)
    assert abs(inst.get("Fz")[0] - Q0) < 1e-3 * Q0   # back near the static load
    inst.fmu.freeFMUstate(state)


def test_wheel_outside_the_panel_is_discarded_with_its_name(instances):
    """A wheel before the first sleeper (x < 0 on the plain track, e.g. a vehicle left at
    x0 = 0 with its rear wheelset behind it): the step is discarded with a message naming
    the wheel and the panel; moved onto the panel, the run proceeds."""
    inst = instances("track2", "off_panel").init(speed=5.0)
    inst.set("x", [-2.5, -2.5])
    with pytest.raises(FMICallException) as err:
        inst.fmu.doStep(0.0, H)
    assert err.value.status == FMI_DISCARD
    assert "wheel1_x = -2.5000 m is outside the modelled panel" in inst.errors()[-1]
    inst.set("x", [X_MID, X_MID])
    inst.fmu.doStep(0.0, H)
    past_end = PARAMS.layout.sleeper_spacing * (PARAMS.layout.sleepers - 1) + 0.1   # m: beyond the last sleeper
    inst.set("x", [X_MID, past_end])
    with pytest.raises(FMICallException):
        inst.fmu.doStep(H, H)
    assert "wheel2_x" in inst.errors()[-1]


def test_non_finite_parameter_is_refused(instances):
    """h1 = NaN: refused at setReal (fmi2Error message), initialization fails, doStep discarded."""
    inst = instances("track2", "nan_param").init(h1=float("nan"))
    assert any("h1" in m and "not finite" in m for m in inst.errors())
    assert np.all(np.isfinite(inst.outputs()))
    with pytest.raises(FMICallException) as err:
        inst.fmu.doStep(0.0, H)
    assert err.value.status == FMI_DISCARD


def test_invalid_parameter_is_reported_not_fatal(instances):
    inst = instances("track2", "bad").init(void_sleeper=16)    # sleepers 0..15
    assert any("void_sleeper" in m for m in inst.errors())
    with pytest.raises(FMICallException) as err:
        inst.fmu.doStep(0.0, H)
    assert err.value.status == FMI_DISCARD


# --------------------------------------------------------------------------- recording
def test_record_file_holds_the_recorded_states_and_the_effective_parameters(instances, tmp_path):
    """record_every = 10 over 100 steps: 11 samples (the initial static state and
    every 10th step), Fz equal to the outputs of those steps; the stored parameters
    are the baked ones with every FMU parameter applied."""
    path = tmp_path / "track_record.npz"
    gaps = (0.0, 1e-4, 3e-4, 3e-4, 1e-4, 0.0)
    inst = instances("track2", "rec").init(
        speed=5.0, extrapolate=True, auto_offset=True, record_every=10, record_file=str(path),
        h1=0.8, h2=1.7, impact_angle=0.012, pad_stiffness=2.0e8, ballast_stiffness_per_length=5e7,
        void_sleeper=6, **{f"void_gap_{j + 1}": g for j, g in enumerate(gaps)})
    out = drive(inst, 0, 100)
    inst.close()
    rec = np.load(path)
    n_dofs = build_track(PARAMS).n
    assert rec["t"].shape == (11,) and rec["q"].shape == rec["v"].shape == (11, n_dofs)
    assert rec["x"].shape == rec["Fz"].shape == (11, 2) and rec["parts"].shape == (11, 2, 2)
    np.testing.assert_allclose(rec["t"], np.arange(11) * 10 * H, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(rec["Fz"][0], Q0)                 # static start
    np.testing.assert_array_equal(rec["Fz"][1:], out[9::10, :2])     # = wheel_Fz after steps 10, 20, ...
    assert float(rec["h"]) == H and float(rec["static_wheel_load"]) == Q0
    expected = dataclasses.replace(
        PARAMS, impact_angle=0.012,
        rail_pad=dataclasses.replace(PARAMS.rail_pad, stiffness=2.0e8, stiffness_scale=1.7),
        ballast=dataclasses.replace(PARAMS.ballast, stiffness_per_length=5e7, stiffness_scale=0.8,
                                    voids=(VoidSpec(6, gaps),)))
    assert track_params_from_dict(json.loads(rec["track_params"].item())) == expected


def test_record_columns_and_stop_time_give_the_full_records_columns_and_the_counters(instances, tmp_path):
    """record_columns = some columns of q and of a (no v), the host's stop time given: the record holds
    exactly those columns of the full record of the same run (the same inputs), with their indices,
    and no v; the monitoring outputs count what the track did (one track step per doStep, at least one
    linear solve and contact sweep each) and are 0 before the first step; malformed columns fail the
    initialization with a message naming the parameter."""
    from track.cosim import state_rows

    n_dofs = build_track(PARAMS).n
    cols = {"q": [0, 5, 17, n_dofs - 1], "a": [3, 4]}
    full_path, part_path = tmp_path / "full.npz", tmp_path / "part.npz"
    full = instances("track2", "rec_full").init(speed=5.0, record_every=10, record_file=str(full_path))
    part = instances("track2", "rec_part")
    part.fmu.setupExperiment(startTime=0.0, stopTime=100 * H)
    part.fmu.enterInitializationMode()
    part.set_parameters(speed=5.0, record_every=10, record_file=str(part_path), record_columns=json.dumps(cols))
    part.fmu.exitInitializationMode()
    counters = ("track_steps", "linear_solves", "contact_iterations", "passes", "factorizations")
    assert part.fmu.getInteger([part.vr[k] for k in counters]) == [0] * 5
    drive(full, 0, 100)
    drive(part, 0, 100)
    steps, solves, sweeps, passes, factors = part.fmu.getInteger([part.vr[k] for k in counters])
    assert steps == 100 and solves >= steps and sweeps >= steps and passes >= steps and factors >= 1
    assert part.fmu.getReal([part.vr["wall_statics"], part.vr["wall_factor"]])[1] > 0.0
    full.close()
    part.close()
    a, b = np.load(full_path), np.load(part_path)
    assert "v" not in b.files and b["q"].shape == (11, 4) and b["a"].shape == (11, 2)
    np.testing.assert_array_equal(b["q_columns"], cols["q"])
    np.testing.assert_array_equal(b["q"], a["q"][:, cols["q"]])   # the same arithmetic: bit-identical
    np.testing.assert_array_equal(b["a"], a["a"][:, cols["a"]])
    np.testing.assert_array_equal(state_rows(dict(b), "q", n_dofs)[:, cols["q"]], a["q"][:, cols["q"]])
    np.testing.assert_array_equal(b["Fz"], a["Fz"])

    bad = instances("track2", "rec_bad").init(record_every=1, record_columns='{"q": [0, "x"]}')
    with pytest.raises(FMICallException):
        bad.fmu.doStep(0.0, H)
    assert any("record_columns" in m for _, m in bad.messages)


# ------------------------------------------------------------------ several FMUs at once
def test_gauss_seidel_with_the_bogie_fmu_in_one_process(instances):
    """Track (4 wheels) and bogie FMUs in one interpreter, Gauss-Seidel with the
    vehicle first for 200 steps at 5 m/s on plain track without irregularity: the
    contact forces stay within 2 % of the static wheel load (the bogie starts in its
    static equilibrium and auto_offset aligns it with the track's)."""
    track = instances("track4", "gs_track").init(speed=5.0, extrapolate=False, auto_offset=True)
    bogie = instances("bogie", "gs_bogie").init(speed=5.0, x0=5.5)
    Fz = track.get("Fz")
    history = []
    for k in range(200):
        bogie.set("Fz", Fz)
        bogie.fmu.doStep(k * H, H)
        for port in ("x", "z", "vz"):
            track.set(port, bogie.get(port))
        track.fmu.doStep(k * H, H)
        Fz = track.get("Fz")
        history.append(Fz)
    history = np.array(history)
    assert np.all(np.isfinite(history))
    assert np.max(np.abs(history / Q0 - 1.0)) < 0.02
    np.testing.assert_allclose(bogie.get("x")[0], 5.5 + 5.0 * 200 * H, rtol=1e-12)
    bundled = {m.split(".")[0] for m in sys.modules if m.startswith("xpanel_")}
    assert any(m.startswith("xpanel_track_") for m in bundled)
    assert any(m.startswith("xpanel_bogie_") for m in bundled)


# ------------------------------------------------------------------------------- build
def test_build_fmus_for_a_scenario(plain_scenario, tmp_path):
    """build-fmus: the track FMU has the scenario vehicle's wheels (bogie: 4) and the
    scenario's speed and wheel load as start values, extrapolate true (what a generic
    fixed-step host needs; issue "FMUs that any FMI tool can load") and the scenario's
    duration and step as DefaultExperiment; both vehicle FMUs are built;
    build_fmu("track") gives the default track for 4 wheels."""
    from orchestrator.cosim.build_job import build_fmus

    built = build_fmus(plain_scenario, tmp_path / "fmus")
    assert sorted(built) == ["bogie", "quarter", "track"] and all(p.is_file() for p in built.values())
    md = read_model_description(str(built["track"]))
    start = {v.name: v.start for v in md.modelVariables}
    assert "wheel4_Fz" in start and "wheel5_Fz" not in start
    assert float(start["speed"]) == plain_scenario.vehicle.speed
    assert float(start["static_wheel_load"]) == 0.5 * plain_scenario.vehicle.axle_load
    assert start["extrapolate"] == "true"      # the accurate choice for a Jacobi-like host
    sim = plain_scenario.simulation
    for kind in ("track", plain_scenario.vehicle.fmu):
        ex = read_model_description(str(built[kind])).defaultExperiment
        assert (float(ex.stopTime), float(ex.stepSize)) == (sim.duration, sim.step), kind
    default = read_model_description(str(build_fmu("track", tmp_path / "default")))
    names = {v.name: v for v in default.modelVariables}
    assert "wheel4_Fz" in names and float(names["impact_angle"].start) == TrackParams().impact_angle


# ------------------------------------------------------------------------- sensor outputs
QUARTER_SCENARIO = "measurement/crossing_quarter_120.yaml"   # sensors: ../sensors/in2track_like.yaml
H_SENSORS = 2e-4        # s: the scenario's communication step
N_SENSOR_STEPS = 40     # steps (8 ms) of a wheelset creeping towards the crossing transition
EPS = np.finfo(float).eps


@pytest.fixture(scope="module")
def crossing_fmu(tmp_path_factory, scenarios_dir):
    """The quarter scenario's track (40-sleeper 1:12 turnout) as a 2-wheel FMU with the
    scenario's sensor layout, resolved and baked by orchestrator.cosim.build_job."""
    from orchestrator.inputs.scenario import load_scenario
    from orchestrator.inputs.sensor_layout import scenario_sensors

    scenario = load_scenario(scenarios_dir / QUARTER_SCENARIO)
    sensors = scenario_sensors(scenario)
    out = tmp_path_factory.mktemp("crossing_fmu")
    path = build_track_fmu(scenario.track, 2, out, name="crossing2", sensors=sensors, speed=2.0,
                           extrapolate=False, static_wheel_load=0.5 * scenario.vehicle.axle_load)
    files = {"crossing2": (path, extract(str(path), unzipdir=str(out / "x")))}
    return {"scenario": scenario, "sensors": sensors, "path": path, "files": files}


def sensor_output_names(sensors) -> list[str]:
    """The FMU's sensor outputs in SensorReader's order: the sensors, then <id>_acc per displacement sensor."""
    return [s.id for s in sensors] + [s.id + "_acc" for s in sensors if s.type == "displacement"]


def creep_to_transition(inst, sensors, k0, n, x_transition):
    """Both wheels 0.5 m before the crossing transition creeping at 2 m/s with a 20 um,
    40 Hz vertical wave; returns the sensor outputs and the wheel outputs after each step."""
    names = sensor_output_names(sensors)
    vrs = [inst.vr[name] for name in names]
    out, wheels = [], []
    for k in range(k0, k0 + n):
        t = k * H_SENSORS
        x = x_transition - 0.5 + 2.0 * t
        phase = 2 * np.pi * 40.0 * t + np.arange(2)
        inst.set("x", [x, x])
        inst.set("z", 2e-5 * np.sin(phase))
        inst.set("vz", 2e-5 * 2 * np.pi * 40.0 * np.cos(phase))
        inst.fmu.doStep(t, H_SENSORS)
        out.append(inst.fmu.getReal(vrs))
        wheels.append(inst.outputs())
    return np.array(out), np.array(wheels)


def test_every_sensor_of_the_layout_is_an_output_with_its_unit(crossing_fmu):
    """DESIGN §4.4: one Real output per sensor id of the scenario's layout, the unit in
    the description and the unit attribute; an <id>_acc accelerometer output per
    displacement sensor; the FMU validates clean and carries the resolved sensors, not
    the layout file."""
    import zipfile

    from orchestrator.inputs.sensor_layout import layout_of

    layout = layout_of(crossing_fmu["scenario"])
    md = read_model_description(str(crossing_fmu["path"]))
    by_name = {v.name: v for v in md.modelVariables}
    units = {"pressure": "Pa", "acceleration": "m/s2", "strain": "-", "displacement": "m"}
    assert {"pressure", "displacement", "acceleration", "strain"} <= set(layout.types.values())
    for sid, kind in layout.types.items():
        v = by_name[sid]
        assert v.causality == "output" and v.type == "Real" and v.variability == "continuous"
        assert v.description.endswith(f"[{units[kind]}]")
        assert v.unit == (None if units[kind] == "-" else units[kind])
        if kind == "displacement":
            acc = by_name[f"{sid}_acc"]
            assert acc.causality == "output" and acc.unit == "m/s2" and acc.description.endswith("[m/s2]")
    assert sum(name.endswith("_acc") for name in by_name) == sum(k == "displacement" for k in layout.types.values())
    assert all(u.dependencies == [] for u in md.outputs)          # functions of the state only
    assert validate_fmu(str(crossing_fmu["path"])) == []
    with zipfile.ZipFile(crossing_fmu["path"]) as zf:
        baked = json.loads(zf.read("resources/track_fmu.json"))
        assert not any(n.endswith(".yaml") for n in zf.namelist())
    assert [s["id"] for s in baked["sensors"]] == layout.ids
    assert {s["body"] for s in baked["sensors"] if s["id"].startswith("A")} == {"sleeper_21"}  # T resolved


def test_sensor_outputs_are_the_sensor_rows_on_the_fmu_state(crossing_fmu, tmp_path):
    """The sensor outputs after each step equal track.sensors.sensor_signals (pressure,
    acceleration, strain; displacement sensors' <id>_acc: their accelerometer) and
    displacement_row @ q (displacement sensors) evaluated in-process on the FMU's own
    states (recorded every step to record_file), on a model rebuilt from the recorded
    effective parameters.

    Tolerance: the states are the FMU's, bit for bit, and the bushing pressures are the
    same elementwise operations on them; what differs is only how the products sum their
    terms (the FMU's rows restricted to their non-zero columns against full rows in
    BLAS, another order and blocking).  Each of two n-term dot products is within
    gamma_n = n eps / (1 - n eps) of |c|.|x| (Higham, Accuracy and Stability, eq. 3.5),
    so they differ by at most 2 gamma_n |c|.|x|, n = the model's 1741 coordinates
    (about 4e-13 relative to |c|.|x|)."""
    from track.layout import build_layout
    from track.sensors import compile_sensors, displacement_row, sensor_signals

    scenario, sensors = crossing_fmu["scenario"], crossing_fmu["sensors"]
    x_transition = build_layout(scenario.track.layout).x_transition
    record = tmp_path / "record.npz"
    inst = Instance(crossing_fmu["files"], "crossing2", "sensors_vs_rows").init(record_every=1,
                                                                               record_file=str(record))
    names = sensor_output_names(sensors)
    try:
        before = np.array(inst.fmu.getReal([inst.vr[n] for n in names]))
        out, wheels = creep_to_transition(inst, sensors, 0, N_SENSOR_STEPS, x_transition)
    finally:
        inst.close()                                       # terminate writes the record
    np.testing.assert_array_equal(before, 0.0)             # documented: 0 until the first step
    assert np.all(np.abs(wheels[:, :2] / (0.5 * scenario.vehicle.axle_load) - 1.0) < 0.05)  # wheels in contact

    rec = np.load(record)
    q, v, a = rec["q"][1:], rec["v"][1:], rec["a"][1:]     # sample 0: the static start, before step 1
    assert q.shape[0] == N_SENSOR_STEPS
    model = build_track(track_params_from_dict(json.loads(rec["track_params"].item())))
    compiled = compile_sensors(model, sensors)
    sig = sensor_signals(model, compiled, q, v, a, H_SENSORS, reconstruct=False)
    D = model.ballast.dof
    p = model.ballast.pressure(q[:, D], v[:, D])
    expected, scale = {}, {}
    for i, s in enumerate(sensors):
        if s.type == "displacement":
            row = displacement_row(model, s.body, s.coord)
            expected[s.id], scale[s.id] = q @ row, np.abs(q) @ np.abs(row)
            expected[s.id + "_acc"], scale[s.id + "_acc"] = sig[s.id], np.abs(a) @ np.abs(compiled.Ca[i])
        else:
            expected[s.id] = sig[s.id]
            scale[s.id] = (np.abs(q) @ np.abs(compiled.Cq[i]) + np.abs(a) @ np.abs(compiled.Ca[i])
                           + np.abs(p) @ np.abs(compiled.Pb[i]))
    n = model.n
    gamma = n * EPS / (1 - n * EPS)
    for j, name in enumerate(names):
        np.testing.assert_array_less(np.abs(out[:, j] - expected[name]), 2 * gamma * scale[name] + 1e-300,
                                     err_msg=name)
    # the signals are the track's response, not zeros: the transition sleeper presses on the
    # ballast, the crossing rail and the sleepers accelerate (the 40 Hz wave), strains vary
    col = {name: out[:, j] for j, name in enumerate(names)}
    assert all(np.all(col[f"A{k}"] > 0.0) for k in (2, 3, 4))     # under the loaded middle of sleeper T
    assert all(np.ptp(col[name]) > 0.0 for name in ("E1", "E2", "B3_acc", "D1", "F1", "B3"))


def test_sensor_reader_matches_sensor_signals_with_open_bushings(scenarios_dir):
    """SensorReader (the FMU's per-step evaluation) against track.sensors on random
    states of a turnout with a void under the transition sleeper, where some bushings
    under the pressure cells are open and some closed: the restricted ballast evaluates
    the same bi-linear law.  Tolerance as in the FMU test above: 2 gamma_n |c|.|x|."""
    from fmus.track_fmu import SensorReader
    from orchestrator.inputs.scenario import load_scenario
    from orchestrator.inputs.sensor_layout import layout_of, resolve
    from track.sensors import compile_sensors, displacement_row, sensor_signals

    scenario = load_scenario(scenarios_dir / QUARTER_SCENARIO)
    void = VoidSpec(21, (0.0, 2e-4, 6e-4, 6e-4, 2e-4, 0.0))          # under the transition sleeper T
    ballast = dataclasses.replace(scenario.track.ballast, voids=(void,))
    params = dataclasses.replace(scenario.track, ballast=ballast)
    model = build_track(params)
    sensors = resolve(layout_of(scenario), model)
    reader = SensorReader(model, sensors)
    compiled = compile_sensors(model, sensors)
    rng = np.random.default_rng(7)
    n, D = model.n, model.ballast.dof
    on_cells = np.flatnonzero(np.any(compiled.Pb != 0.0, axis=0))
    gamma = n * EPS / (1 - n * EPS)
    n_open = 0
    for _ in range(20):
        q = rng.normal(-4e-4, 4e-4, n)          # m: bushings around their gap, some open, some closed
        v, a = rng.normal(0.0, 1e-2, n), rng.normal(0.0, 10.0, n)
        got = reader.read(q, v, a).copy()
        sig = sensor_signals(model, compiled, q, v, a, H_SENSORS, reconstruct=False)
        p = model.ballast.pressure(q[D], v[D])
        n_open += int(np.sum(p[on_cells] == 0.0))
        expected, scale = [], []
        for i, s in enumerate(sensors):
            if s.type == "displacement":
                row = displacement_row(model, s.body, s.coord)
                expected.append(q @ row)
                scale.append(np.abs(q) @ np.abs(row))
            else:
                expected.append(sig[s.id][0])
                scale.append(np.abs(q) @ np.abs(compiled.Cq[i]) + np.abs(a) @ np.abs(compiled.Ca[i])
                             + np.abs(p) @ np.abs(compiled.Pb[i]))
        for i, s in enumerate(sensors):      # then the accelerometers of the displacement sensors
            if s.type == "displacement":
                expected.append(sig[s.id][0])
                scale.append(np.abs(a) @ np.abs(compiled.Ca[i]))
        np.testing.assert_array_less(np.abs(got - np.array(expected)), 2 * gamma * np.array(scale) + 1e-300)
    assert 0 < n_open < 20 * on_cells.size       # both branches of the ballast law were exercised


def test_fmu_state_round_trip_restores_the_sensor_outputs(crossing_fmu):
    """get state, step, set state: the sensor outputs read right after the restore are
    those of the saved point, and the steps repeat bit-identically (wheel and sensor
    outputs), also through serialisation into a second instance."""
    from track.layout import build_layout

    sensors = crossing_fmu["sensors"]
    x_t = build_layout(crossing_fmu["scenario"].track.layout).x_transition
    names = sensor_output_names(sensors)
    inst = Instance(crossing_fmu["files"], "crossing2", "sensor_state_a").init()
    other = Instance(crossing_fmu["files"], "crossing2", "sensor_state_b").init()
    try:
        creep_to_transition(inst, sensors, 0, 5, x_t)
        state = inst.fmu.getFMUstate()
        at_save = np.array(inst.fmu.getReal([inst.vr[n] for n in names]))
        first = creep_to_transition(inst, sensors, 5, 10, x_t)
        assert np.ptp(first[0][:, names.index("E1")]) > 0.0    # the outputs do change over the steps
        inst.fmu.setFMUstate(state)
        assert np.array_equal(inst.fmu.getReal([inst.vr[n] for n in names]), at_save)
        second = creep_to_transition(inst, sensors, 5, 10, x_t)
        assert all(np.array_equal(f, s) for f, s in zip(first, second))
        blob = inst.fmu.serializeFMUstate(state)
        inst.fmu.freeFMUstate(state)
        other.fmu.setFMUstate(other.fmu.deSerializeFMUstate(blob))
        assert np.array_equal(other.fmu.getReal([other.vr[n] for n in names]), at_save)
        third = creep_to_transition(other, sensors, 5, 10, x_t)
        assert all(np.array_equal(f, t) for f, t in zip(first, third))
    finally:
        inst.close()
        other.close()


def test_build_job_sensor_layout_policy(plain_scenario, scenarios_dir):
    """The default layout is drawn for a turnout: on the plain track it does not fit,
    so build_fmus bakes no sensors and warns, naming them (a UserInputWarning, printed by
    the command line); a layout the scenario names must fit."""
    from orchestrator.inputs.errors import UserInputError, UserInputWarning
    from orchestrator.inputs.sensor_layout import scenario_sensors

    with pytest.warns(UserInputWarning, match="default sensor layout does not fit this track: A5, A6, B1"):
        assert scenario_sensors(plain_scenario) == []
    named = dataclasses.replace(plain_scenario, sensors=str(scenarios_dir / "sensors" / "in2track_like.yaml"))
    with pytest.raises(UserInputError, match="A5"):
        scenario_sensors(named)


def test_sensor_outputs_of_the_compiled_steps_are_the_python_steps(crossing_fmu, monkeypatch):
    """Sensor outputs read after every step: with the compiled steps the shim evaluates them itself (lazily,
    track.unit_step.sensor_read), without them Python evaluates the same function: equal to the last bit, wheel
    outputs too, and the steps stayed compiled while they were read (python_steps 1 against 40). That the reads
    themselves do not enter Python is not observable through FMI; benchmarks/bench_fmu_fast.py measures it."""
    from track.layout import build_layout

    sensors = crossing_fmu["sensors"]
    x_t = build_layout(crossing_fmu["scenario"].track.layout).x_transition
    runs = {}
    for mode in ("0", "1"):
        monkeypatch.setenv("XPANEL_FMU_FAST", mode)
        inst = Instance(crossing_fmu["files"], "crossing2", f"sensors_{mode}").init()
        try:
            out, wheels = creep_to_transition(inst, sensors, 0, N_SENSOR_STEPS, x_t)
            runs[mode] = (out, wheels, inst.fmu.getInteger([inst.vr["python_steps"]])[0])
        finally:
            inst.close()
    (out0, wheels0, n0), (out1, wheels1, n1) = runs["0"], runs["1"]
    assert np.ptp(out0, axis=0).max() > 0.0            # the sensors respond
    assert np.array_equal(out0, out1) and np.array_equal(wheels0, wheels1)
    assert n0 == N_SENSOR_STEPS and n1 == 1
