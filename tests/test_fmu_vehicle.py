"""Vehicle FMUs standalone in FMPy: validation, statics, dynamics, FMU state, errors."""
from __future__ import annotations

import logging
import sys

import numpy as np
import pytest

fmpy = pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

from fmpy import calloc, extract, free, read_model_description, simulate_fmu  # noqa: E402
from fmpy.fmi1 import FMICallException  # noqa: E402
from fmpy.fmi2 import (  # noqa: E402
    FMU2Slave,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
)
from fmpy.validation import validate_fmu  # noqa: E402

from fmus.build import build_fmu  # noqa: E402
from vehicle import BogieParams, QuarterParams, VehicleStepper, bogie, quarter_vehicle  # noqa: E402

FMI_DISCARD = 2
KINDS = ("bogie", "quarter")
N_WHEELS = {"bogie": 4, "quarter": 2}


@pytest.fixture(scope="session")
def fmu_files(tmp_path_factory):
    """Both vehicle FMUs, built once per session, and their extracted directories."""
    out = tmp_path_factory.mktemp("fmus")
    files = {}
    for kind in KINDS:
        path = build_fmu(kind, out)
        files[kind] = (path, extract(str(path), unzipdir=str(out / f"{kind}_x")))
    return files


class Instance:
    """An FMU2Slave with name -> value reference lookup and captured log messages."""

    def __init__(self, fmu_files, kind: str, name: str | None = None):
        path, unzipdir = fmu_files[kind]
        self.md = read_model_description(str(path))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.messages: list[tuple[int, str]] = []
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=unzipdir,
                             modelIdentifier=self.md.coSimulation.modelIdentifier,
                             instanceName=name or kind)
        self._callbacks = fmi2CallbackFunctions()   # kept alive as long as the instance
        self._callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        self._callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self._callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        self.fmu.instantiate(callbacks=self._callbacks, loggingOn=True)
        self.n = N_WHEELS[kind]

    def _log(self, component, instance, status, category, message):
        self.messages.append((status, message.decode()))

    def init(self, **parameters):
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        for name, value in parameters.items():
            if isinstance(value, bool):
                self.fmu.setBoolean([self.vr[name]], [value])
            else:
                self.fmu.setReal([self.vr[name]], [float(value)])
        self.fmu.exitInitializationMode()
        return self

    def set(self, name, values):
        self.fmu.setReal([self.vr[f"wheel{i + 1}_{name}"] for i in range(self.n)], list(values))

    def get(self, name):
        return np.array(self.fmu.getReal([self.vr[f"wheel{i + 1}_{name}"] for i in range(self.n)]))

    def outputs(self):
        return np.concatenate([self.get("x"), self.get("z"), self.get("vz")])

    def close(self):
        self.fmu.terminate()
        self.fmu.freeInstance()


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


def python_model(kind, **params):
    return bogie(BogieParams(**params)) if kind == "bogie" else quarter_vehicle(QuarterParams(**params))


# ------------------------------------------------------------------------ description
@pytest.mark.parametrize("kind", KINDS)
def test_fmpy_validation_reports_no_problems(fmu_files, kind):
    assert validate_fmu(str(fmu_files[kind][0])) == []


def test_bundled_modules_load_from_their_bytecode(fmu_files):
    """Every bundled module of the FMU has its hash-checked bytecode in the archive (fmus.build,
    module docstring), and importing the unzipped package compiles none of the bundled sources
    (checked in a fresh interpreter, counting calls of the import system's compile step). On the
    old build each of these modules was compiled again in every process that loaded the FMU."""
    import subprocess
    import zipfile

    path, unzipped = fmu_files["bogie"]
    names = set(zipfile.ZipFile(path).namelist())
    sources = [n for n in names if n.endswith(".py") and n.count("/") >= 2]   # in a package below resources/
    assert sources
    tag = sys.implementation.cache_tag
    missing = [n for n in sources
               if "{}/__pycache__/{}.{}.pyc".format(n.rsplit("/", 1)[0], n.rsplit("/", 1)[1][:-3], tag) not in names]
    assert not missing, missing
    package = next(n.split("/")[1] for n in sources if n.split("/")[1].startswith("xpanel_"))
    probe = ("import importlib, importlib._bootstrap_external as be, sys\n"
             "seen = []\n"
             "orig = be.SourceLoader.source_to_code\n"
             "be.SourceLoader.source_to_code = lambda self, data, path, *a, **k: (seen.append(path), "
             "orig(self, data, path, *a, **k))[1]\n"
             f"importlib.import_module('{package}.vehicle_fmus')\n"
             "print([p for p in seen if '{0}' in p])\n".format(package))
    out = subprocess.run([sys.executable, "-c", probe], cwd=str(unzipped) + "/resources", capture_output=True,
                         text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout


@pytest.mark.parametrize("kind", KINDS)
def test_model_description_ports_units_and_capabilities(fmu_files, kind):
    md = read_model_description(str(fmu_files[kind][0]))
    n = N_WHEELS[kind]
    by_name = {v.name: v for v in md.modelVariables}
    assert md.coSimulation.canGetAndSetFMUstate and md.coSimulation.canSerializeFMUstate
    for i in range(1, n + 1):
        assert by_name[f"wheel{i}_Fz"].causality == "input"
        assert by_name[f"wheel{i}_Fz"].description.endswith("[N]")
        assert by_name[f"wheel{i}_Fz"].unit == "N"
        for port, unit in (("x", "m"), ("z", "m"), ("vz", "m/s")):
            v = by_name[f"wheel{i}_{port}"]
            assert v.causality == "output" and v.description.endswith(f"[{unit}]") and v.unit == unit
        assert by_name[f"wheel{i}_z0"].causality == "parameter"
    # every variable states its unit in the description
    assert all(v.description.rstrip().endswith("]") for v in md.modelVariables)
    # the input start value is the static wheel load of the default vehicle
    assert float(by_name["wheel1_Fz"].start) == pytest.approx(196200.0 / 2, rel=1e-12)
    # outputs have no direct feed-through; initial wheel_z depends on its wheel_z0 only
    assert all(u.dependencies == [] for u in md.outputs)
    initial = {u.variable.name: [d.name for d in u.dependencies] for u in md.initialUnknowns}
    assert initial["wheel1_z"] == ["wheel1_z0"]


# ----------------------------------------------------------------------------- statics
@pytest.mark.parametrize("kind", KINDS)
def test_static_loads_hold_static_positions(instances, kind):
    """Prescribed Fz = static loads: the wheels stay at wheel_z0 (no drop), wheel_x
    moves at the set speed.  1e-12 m covers rounding in 2000 exact steps."""
    inst = instances(kind)
    n = inst.n
    z0 = {"bogie": [-1.0e-3, -1.2e-3, -0.9e-3, -1.1e-3],  # no twist: equal cross-level 0.2 mm
          "quarter": [-1.0e-3, -1.3e-3]}[kind]
    params = {f"wheel{i + 1}_z0": z for i, z in enumerate(z0)}
    inst.init(speed=25.0, x0=12.0, **params)
    np.testing.assert_allclose(inst.get("z"), z0, rtol=0, atol=1e-15)
    inst.set("Fz", [196200.0 / 2] * n)
    h = 1e-4
    for k in range(2000):
        inst.fmu.doStep(k * h, h)
    np.testing.assert_allclose(inst.get("z"), z0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(inst.get("vz"), 0.0, atol=1e-10)
    offsets = python_model(kind).wheel_offsets
    np.testing.assert_allclose(inst.get("x"), 12.0 + offsets + 25.0 * 2000 * h, rtol=1e-14)
    assert not [m for s, m in inst.messages if s >= 1]   # no warning: loads were consistent


def test_unconnected_fmu_with_changed_parameters_holds_equilibrium(fmu_files, tmp_path):
    """fmpy.simulate_fmu with no inputs: an input never set takes the static load of the
    actual parameters (here a lighter, rigid quarter vehicle), so nothing moves."""
    path = fmu_files["quarter"][0]
    res = simulate_fmu(str(path), stop_time=0.05, output_interval=1e-3,
                       start_values={"axle_load": 150e3, "flexible": False,
                                     "wheel1_z0": -0.5e-3, "wheel2_z0": -0.7e-3},
                       output=["wheel1_z", "wheel2_z", "wheel1_Fz"])
    np.testing.assert_allclose(res["wheel1_z"], -0.5e-3, rtol=0, atol=1e-12)
    np.testing.assert_allclose(res["wheel2_z"], -0.7e-3, rtol=0, atol=1e-12)
    np.testing.assert_allclose(res["wheel1_Fz"], 75e3, rtol=1e-12)


def test_initial_unknowns_follow_parameters_in_initialization_mode(instances):
    """Before exitInitializationMode the outputs are the declared functions of the
    parameters: x = x0 + a_i (a_i from the wheelbase), z = wheel_z0, vz = 0."""
    inst = instances("bogie")
    inst.fmu.setupExperiment(startTime=0.0)
    inst.fmu.enterInitializationMode()
    inst.fmu.setReal([inst.vr["x0"], inst.vr["wheelbase"], inst.vr["wheel3_z0"]], [7.0, 2.7, -1e-3])
    np.testing.assert_array_equal(inst.get("x"), [7.0, 7.0, 7.0 - 2.7, 7.0 - 2.7])
    np.testing.assert_array_equal(inst.get("z"), [0.0, 0.0, -1e-3, 0.0])
    np.testing.assert_array_equal(inst.get("vz"), 0.0)


def test_inconsistent_start_forces_are_warned(instances):
    """Nominal loads on a twisted wheel set-up are not an equilibrium of the bogie
    (statically indeterminate): the FMU says so at initialization."""
    inst = instances("bogie")
    inst.fmu.setupExperiment(startTime=0.0)
    inst.fmu.enterInitializationMode()
    inst.set("Fz", [196200.0 / 2] * 4)
    inst.fmu.setReal([inst.vr["wheel1_z0"], inst.vr["wheel2_z0"]], [1e-3, -2e-3])
    inst.fmu.exitInitializationMode()
    assert any("static wheel loads" in m for s, m in inst.messages if s == 1)


# ---------------------------------------------------------------------------- dynamics
@pytest.mark.parametrize("kind", KINDS)
def test_step_response_matches_python_model(instances, kind):
    """A force step on wheel 1 (+20 kN) gives the same response in the FMU as the
    pure-Python model stepped with the same h (same algorithm; round-off: see the tolerance)."""
    k1 = 1.5e6
    inst = instances(kind).init(k1=k1)
    veh = python_model(kind, k1=k1)
    st = veh.static_state(np.zeros(veh.n_wheels))
    F = st.Fz.copy()
    F[0] += 2e4
    h = 2e-4
    ref = VehicleStepper(veh, h, q0=st.q, Fz0=st.Fz)
    fmu_z, ref_z = [], []
    inst.set("Fz", F)
    for k in range(500):
        inst.fmu.doStep(k * h, h)
        ref.step(F)
        fmu_z.append(np.concatenate([inst.get("z"), inst.get("vz")]))
        ref_z.append(np.concatenate([ref.wheel_z, ref.wheel_vz]))
    fmu_z, ref_z = np.array(fmu_z), np.array(ref_z)
    scale = np.abs(ref_z).max(axis=0)
    # the FMU steps in its C shim (fmus.fast: y <- G z summed in index order) where numpy's BLAS sums in
    # an order of its own: the same algorithm, different round-off, grown over 500 steps of a lightly
    # damped system (measured 2026-11-26: <= 3e-12 of each signal's range)
    assert np.all(np.abs(fmu_z - ref_z) <= 1e-10 * scale)
    assert np.ptp(ref_z[:, 0]) > 1e-5       # the step really moved wheel 1 (> 10 um)


def test_step_size_change_is_handled(instances):
    """doStep with a new h re-discretises: 10 steps of h then 20 of h/2 match the
    Python model doing the same (1e-12 relative)."""
    inst = instances("quarter").init()
    veh = python_model("quarter")
    st = veh.static_state(np.zeros(2))
    F = st.Fz + np.array([1e4, -5e3])
    inst.set("Fz", F)
    ref = VehicleStepper(veh, 1e-3, q0=st.q, Fz0=st.Fz)
    t = 0.0
    for h, n in ((1e-3, 10), (5e-4, 20)):
        ref.set_step(h)
        for _ in range(n):
            inst.fmu.doStep(t, h)
            ref.step(F)
            t += h
    np.testing.assert_allclose(inst.get("z"), ref.wheel_z, rtol=1e-12)


# --------------------------------------------------------------------------- FMU state
@pytest.mark.parametrize("kind", KINDS)
def test_fmu_state_round_trip_is_bit_identical(instances, kind):
    """get state, run N steps, set state, run again: identical outputs, also through
    serialisation (fmi2SerializeFMUstate / fmi2DeSerializeFMUstate)."""
    inst = instances(kind).init(x0=3.0)
    rng = np.random.default_rng(7)
    h = 1e-4
    forces = 196200.0 / 2 + rng.normal(scale=1e4, size=(60, inst.n))

    def run(k0):
        for k in range(k0, k0 + 30):
            inst.set("Fz", forces[k])
            inst.fmu.doStep(k * h, h)
        return inst.outputs()

    run(0)
    state = inst.fmu.getFMUstate()
    first = run(30)
    inst.fmu.setFMUstate(state)
    second = run(30)
    assert np.array_equal(first, second)
    blob = inst.fmu.serializeFMUstate(state)
    inst.fmu.setFMUstate(inst.fmu.deSerializeFMUstate(blob))
    third = run(30)
    assert np.array_equal(first, third)
    inst.fmu.freeFMUstate(state)


def test_fmu_state_restores_parameters_and_time(instances):
    """A state taken in one run restores the stepper and the clock of that run: the
    wheel positions x continue from the saved time."""
    inst = instances("bogie").init(speed=10.0)
    h = 1e-3
    for k in range(5):
        inst.fmu.doStep(k * h, h)
    state = inst.fmu.getFMUstate()
    x_saved = inst.get("x")
    for k in range(5, 50):
        inst.fmu.doStep(k * h, h)
    inst.fmu.setFMUstate(state)
    np.testing.assert_array_equal(inst.get("x"), x_saved)


# ------------------------------------------------------------------------------ errors
def test_nan_input_is_discarded_without_crash(instances, caplog):
    inst = instances("bogie").init()
    h = 1e-4
    for k in range(10):
        inst.fmu.doStep(k * h, h)
    before = inst.outputs()
    inst.fmu.setReal([inst.vr["wheel2_Fz"]], [float("nan")])
    with caplog.at_level(logging.ERROR), pytest.raises(FMICallException) as err:
        inst.fmu.doStep(10 * h, h)
    assert err.value.status == FMI_DISCARD
    assert np.array_equal(inst.outputs(), before)          # state kept at t = 10 h
    errors = [m for s, m in inst.messages if s == 3]       # fmi2Error messages
    assert errors and "wheel2_Fz" in errors[-1] and "non-finite" in errors[-1]
    assert any("wheel2_Fz" in r.getMessage() for r in caplog.records)
    inst.fmu.setReal([inst.vr["wheel2_Fz"]], [float("inf")])
    with pytest.raises(FMICallException):
        inst.fmu.doStep(10 * h, h)
    # the instance is alive: a finite input continues the simulation
    inst.set("Fz", [196200.0 / 2] * 4)
    inst.fmu.doStep(10 * h, h)
    assert np.all(np.isfinite(inst.outputs()))


def test_invalid_parameter_is_reported_not_fatal(instances):
    inst = instances("quarter").init(k1=-1.0)
    assert any("k1" in m for s, m in inst.messages if s == 3)
    with pytest.raises(FMICallException) as err:
        inst.fmu.doStep(0.0, 1e-4)
    assert err.value.status == FMI_DISCARD


@pytest.mark.parametrize("value", [float("nan"), float("inf")])
def test_non_finite_parameter_is_refused_and_discards(instances, value):
    """speed = NaN (or inf) on the quarter FMU: refused when set (fmi2Error message naming
    it; the outputs keep finite values), initialization fails with that message and doStep
    is discarded: never fmi2OK with NaN outputs."""
    inst = instances("quarter").init(speed=value)
    errors = [m for s, m in inst.messages if s == 3]        # fmi2Error messages
    assert errors and all("speed" in m and "not finite" in m for m in errors)
    assert np.all(np.isfinite(inst.outputs()))
    with pytest.raises(FMICallException) as err:
        inst.fmu.doStep(0.0, 1e-4)
    assert err.value.status == FMI_DISCARD
    assert "speed" in [m for s, m in inst.messages if s == 3][-1]


def test_finite_value_after_a_refused_one_initializes(instances):
    """A NaN set and then replaced by a finite value before exitInitializationMode: the run
    proceeds with the finite value (x = x0 + speed t, 1e-12 relative: rounding)."""
    inst = instances("quarter")
    inst.fmu.setupExperiment(startTime=0.0)
    inst.fmu.enterInitializationMode()
    inst.fmu.setReal([inst.vr["speed"]], [float("nan")])
    inst.fmu.setReal([inst.vr["speed"]], [20.0])
    inst.fmu.exitInitializationMode()
    inst.fmu.doStep(0.0, 1e-3)
    # x = speed * t after one step: the refused NaN left no trace (rtol: round-off of one product)
    np.testing.assert_allclose(inst.get("x")[0], 20.0 * 1e-3, rtol=1e-12)


# ------------------------------------------------------------------ several FMUs at once
def test_bogie_and_quarter_in_one_process(instances):
    """Both FMUs (and two bogie instances) step interleaved in one interpreter, each
    with its own bundled, uniquely named code, each matching its Python model."""
    b1 = instances("bogie", "bogie_a").init()
    b2 = instances("bogie", "bogie_b").init(k2=0.8e6)
    q = instances("quarter", "quarter_a").init(flexible=False)
    models = [(b1, python_model("bogie")), (b2, python_model("bogie", k2=0.8e6)),
              (q, python_model("quarter", flexible=False))]
    h = 2e-4
    refs = []
    for inst, veh in models:
        st = veh.static_state(np.zeros(veh.n_wheels))
        F = st.Fz.copy()
        F[-1] -= 1.5e4
        inst.set("Fz", F)
        refs.append((VehicleStepper(veh, h, q0=st.q, Fz0=st.Fz), F))
    for k in range(200):
        for (inst, _), (ref, F) in zip(models, refs):
            inst.fmu.doStep(k * h, h)
            ref.step(F)
    for (inst, _), (ref, _) in zip(models, refs):
        # round-off of another summation order (test_step_response_matches_python_model; measured <= 2.3e-12)
        np.testing.assert_allclose(inst.get("z"), ref.wheel_z, rtol=1e-10)
    # the two bogies differ (different k2), so instances do not share state
    assert not np.array_equal(b1.get("z"), b2.get("z"))
    bundled = {m.split(".")[0] for m in sys.modules if m.startswith("xpanel_")}
    assert any(m.startswith("xpanel_bogie_") for m in bundled)
    assert any(m.startswith("xpanel_quarter_") for m in bundled)


@pytest.mark.parametrize("mode", ["bounce", "pitch"])
def test_bogie_fmu_bounce_and_pitch_frequencies_in_fmpy(instances, mode):
    """The bogie FMU in FMPy, its contact forces prescribed by the test host.

    The host holds the wheels with a stiff, damped contact law, Fz = Q0 - k_g z - c_g vz
    (k_g = 5e8 N/m; c_g = 1e6 N s/m damps the ~130 Hz wheelset-on-k_g mode within a few
    periods and stiffens the support by < 10 % at the frame's frequencies),
    after a 5 ms force pulse on all wheels (bounce) or front +/rear - (pitch), with the
    suspension dampers set to 0 through FMU parameters. The frame then oscillates on its
    primary springs with the wheelsets (nearly) held: the analytic 2-DOF values of
    vehicle.bogie.bounce_pitch_frequencies. Tolerance 1 %: k_g in series with the primary
    springs lowers them by 0.1 %, the free 34 t car body (~1 Hz on the secondary) moves
    them by < 0.3 %, and the frequency is read from zero crossings over ~1.5 s.
    """
    from vehicle.bogie import bounce_pitch_frequencies

    f_b, f_p = bounce_pitch_frequencies(BogieParams())
    f_expected = f_b if mode == "bounce" else f_p
    inst = instances("bogie", f"modes_{mode}").init(c1=0.0, c2=0.0)
    h, k_g, Q0 = 1e-4, 5e8, 196200.0 / 2
    pulse = np.array([1, 1, 1, 1.0]) if mode == "bounce" else np.array([1, 1, -1, -1.0])
    n = int(2.0 / h)
    F = np.empty((n, 4))
    for k in range(n):
        z, vz = inst.get("z"), inst.get("vz")
        Fz = Q0 - k_g * z - 1e6 * vz + (2e4 * pulse if k * h < 5e-3 else 0.0)
        inst.set("Fz", Fz)
        inst.fmu.doStep(k * h, h)
        F[k] = Fz
    # the frame mode: the contact-force signal of wheel 1 (front) minus its mean over the
    # record; only zero crossings after the pulse, frequency from their spacing
    sig = F[int(0.3 / h):, 0] - Q0
    if mode == "pitch":
        sig = sig - F[int(0.3 / h):, 2] + Q0   # front minus rear removes the car-body bounce
    else:
        sig = sig - np.convolve(sig, np.ones(int(0.5 / h)) / int(0.5 / h), mode="same")  # drop ~1 Hz
        sig = sig[int(0.3 / h):-int(0.3 / h)]
    s = np.sign(sig)
    idx = np.flatnonzero(s[1:] * s[:-1] < 0)
    f_meas = (len(idx) - 1) / 2 / ((idx[-1] - idx[0]) * h)
    print(f"bogie FMU {mode}: {f_meas:.3f} Hz, analytic {f_expected:.3f} Hz")
    assert abs(f_meas / f_expected - 1) < 0.01, (f_meas, f_expected)


def test_compiled_steps_in_the_shim_follow_the_python_steps(instances, monkeypatch):
    """The bogie FMU stepped by its C shim (fmus.fast, xpanel_lti_step) against its Python path
    (XPANEL_FMU_FAST=0), the same force history with a step on wheel 1: the Python path is the
    Python model's stepper to the last bit; the shim's steps agree to round-off (index-order sums
    against numpy's BLAS: measured <= 3e-12 of the range, 1e-10 allowed), and python_steps shows
    that the shim took every step but the first (and the one after a step size change)."""
    veh = python_model("bogie")
    st = veh.static_state(np.zeros(veh.n_wheels))
    h = 2e-4
    runs = {}
    for mode in ("0", "1"):
        monkeypatch.setenv("XPANEL_FMU_FAST", mode)
        inst = instances("bogie", f"shim_{mode}").init()
        ref = VehicleStepper(veh, h, q0=st.q, Fz0=st.Fz)
        out, ref_out = [], []
        for k in range(300):
            F = st.Fz + (2e4 if k >= 10 else 0.0) * np.eye(veh.n_wheels)[0]
            inst.set("Fz", F)
            step = h if k < 250 else h / 2       # a step size change at k = 250: Python re-discretises
            if k == 250:
                ref.set_step(step)
            inst.fmu.doStep(k * h if k <= 250 else 250 * h + (k - 250) * step, step)
            ref.step(F)
            out.append(np.concatenate([inst.get("x"), inst.get("z"), inst.get("vz")]))
            ref_out.append(np.concatenate([ref.wheel_z, ref.wheel_vz]))
        runs[mode] = (np.array(out), np.array(ref_out),
                      inst.fmu.getInteger([inst.vr["python_steps"]])[0])
    (py, ref_z, n_py), (fast, _, n_fast) = runs["0"], runs["1"]
    m = veh.n_wheels
    assert np.array_equal(py[:, m:], ref_z)
    scale = np.abs(ref_z).max(axis=0)
    assert np.all(np.abs(fast[:, m:] - ref_z) <= 1e-10 * scale)
    assert np.array_equal(fast[:, :m], py[:, :m])     # x = x0 + a_i + speed t, the same operations
    assert n_py == 300 and n_fast == 2
