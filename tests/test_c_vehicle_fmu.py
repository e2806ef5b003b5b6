"""The third-party C vehicle FMU (tests/fixtures/c_vehicle) standalone in FMPy.

The FMU is the rigid quarter vehicle of :mod:`vehicle.quarter` written in C with other
conventions (z, vz and contact force positive DOWNWARD; wheels at 0 in the initial
static state), compiled here with the system C compiler.  Checked: FMPy validation,
statics, dynamics against the exact-discretisation Python stepper, FMU state
round trips and error handling.
"""
from __future__ import annotations

import zipfile

import numpy as np
import pytest

fmpy = pytest.importorskip("fmpy")

from c_vehicle import MODEL_IDENTIFIER, build_c_vehicle_fmu, find_c_compiler, fmu_platform  # noqa: E402

if find_c_compiler() is None:
    pytest.skip("no C compiler (cc or gcc) on PATH: cannot build the C vehicle FMU",
                allow_module_level=True)
try:
    PLATFORM, LIB_SUFFIX = fmu_platform()
except RuntimeError as exc:
    pytest.skip(str(exc), allow_module_level=True)

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

from vehicle import GRAVITY, QuarterParams, VehicleStepper, quarter_vehicle  # noqa: E402

OUTPUTS = ("axle1.zL", "axle1.zR", "axle1.vzL", "axle1.vzR")
INPUTS = ("axle1.FL", "axle1.FR")
PARAMETERS = ("v", "s0", "m_body", "m_axle", "J_body", "J_axle", "k_prim", "c_prim", "b_prim", "b_wheel")
STATIC_LOAD = 196200.0 / 2          # N per wheel with the default parameters (upward, our convention)


@pytest.fixture(scope="module")
def c_fmu(tmp_path_factory):
    """(fmu path, extracted directory, model description), built once per module."""
    out = tmp_path_factory.mktemp("c_vehicle")
    path = build_c_vehicle_fmu(out)
    return path, extract(str(path), unzipdir=str(out / "x")), read_model_description(str(path))


class Instance:
    """An initialised FMU2Slave of the C vehicle, with name lookup and captured log messages."""

    def __init__(self, c_fmu, name="c_vehicle", start=None, start_time=0.0, initialize=True):
        path, unzipdir, md = c_fmu
        self.md = md
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.messages: list[tuple[int, str]] = []
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir,
                             modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
        self._callbacks = fmi2CallbackFunctions()   # kept alive as long as the instance
        self._callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        self._callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self._callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        self.fmu.instantiate(callbacks=self._callbacks, loggingOn=False)
        self.t = start_time
        self.fmu.setupExperiment(startTime=start_time)
        for key, value in (start or {}).items():
            self.set(key, value)
        if initialize:
            self.initialize()

    def initialize(self):
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()

    def _log(self, component, instance, status, category, message):
        self.messages.append((status, message.decode()))

    def get(self, *names) -> np.ndarray:
        return np.array(self.fmu.getReal([self.vr[n] for n in names]))

    def set(self, name, value):
        self.fmu.setReal([self.vr[name]], [float(value)])

    def step(self, FL, FR, h):
        """Set the inputs (downward +) and advance by h."""
        self.fmu.setReal([self.vr["axle1.FL"], self.vr["axle1.FR"]], [float(FL), float(FR)])
        self.fmu.doStep(self.t, h)
        self.t += h

    def close(self):
        try:
            self.fmu.terminate()
        except FMICallException:
            pass
        self.fmu.freeInstance()


@pytest.fixture
def instance(c_fmu):
    inst = Instance(c_fmu)
    yield inst
    inst.close()


def force_history(kind: str, n: int, h: float, static_load: float = STATIC_LOAD) -> np.ndarray:
    """Contact forces in OUR convention (upward +), shape (n, 2), one row per step."""
    t = np.arange(n) * h
    F = np.full((n, 2), static_load)
    if kind == "left_step":            # +20 kN on the left wheel from t = 10 ms on
        F[t >= 0.01, 0] += 20e3
    elif kind == "doublet":            # zero net impulse: vibration, no rigid-body drift
        F[(t >= 0.01) & (t < 0.03), 0] += 20e3
        F[(t >= 0.03) & (t < 0.05), 0] -= 20e3
        F[:, 1] += 5e3 * np.sin(2 * np.pi * 15.0 * t) * (t < 2 / 15.0)
    else:
        raise ValueError(kind)
    return F


def step_sizes(kind: str, n: int) -> np.ndarray:
    if kind == "fixed":
        return np.full(n, 1e-3)
    return np.array([1e-3, 2.5e-4, 5e-4, 1.3e-3])[np.arange(n) % 4]   # variable communication steps


# ------------------------------------------------------------------ packaging
def test_validates_without_problems(c_fmu):
    path, _, _ = c_fmu
    assert validate_fmu(str(path)) == []


def test_model_description_and_layout(c_fmu):
    path, _, md = c_fmu
    assert md.fmiVersion == "2.0"
    assert md.coSimulation is not None and md.modelExchange is None
    cs = md.coSimulation
    assert cs.modelIdentifier == MODEL_IDENTIFIER
    assert cs.canGetAndSetFMUstate and cs.canSerializeFMUstate
    assert cs.canHandleVariableCommunicationStepSize
    with zipfile.ZipFile(path) as zf:
        names = zf.namelist()
        assert all(info.compress_type == zipfile.ZIP_DEFLATED for info in zf.infolist())
    assert sorted(names) == sorted(["modelDescription.xml", f"binaries/{PLATFORM}/{MODEL_IDENTIFIER}{LIB_SUFFIX}"])
    var = {v.name: v for v in md.modelVariables}
    for name in ("axle1.s",) + OUTPUTS:
        assert (var[name].causality, var[name].variability, var[name].initial) == ("output", "continuous", "calculated")
    for name in INPUTS:
        assert var[name].causality == "input" and float(var[name].start) == -STATIC_LOAD
    for name in PARAMETERS:
        assert (var[name].causality, var[name].variability, var[name].initial) == ("parameter", "fixed", "exact")
    assert [u.variable.name for u in md.outputs] == ["axle1.s", *OUTPUTS]
    assert all(u.dependencies == [] for u in md.outputs[1:])     # no direct feedthrough


def test_start_values_agree_with_c_defaults(c_fmu, instance):
    _, _, md = c_fmu
    for v in md.modelVariables:
        if v.start is not None:
            assert instance.get(v.name)[0] == float(v.start), v.name
    assert float(md.modelVariables[[v.name for v in md.modelVariables].index("m_body")].start) \
        == QuarterParams().sprung_mass


def test_wrong_guid_is_refused(c_fmu):
    _, unzipdir, md = c_fmu
    messages = []
    callbacks = fmi2CallbackFunctions()
    callbacks.logger = fmi2CallbackLoggerTYPE(lambda c, i, status, cat, msg: messages.append(msg.decode()))
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    fmu = FMU2Slave(guid="{00000000-0000-0000-0000-000000000000}", unzipDirectory=unzipdir,
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName="wrong")
    try:
        with pytest.raises(Exception, match="instantiate"):
            fmu.instantiate(callbacks=callbacks)
    finally:
        fmu.freeLibrary()
    assert any("wrong GUID" in m for m in messages), messages


# -------------------------------------------------------------------- statics
@pytest.mark.parametrize("start", [{}, {"m_body": 24000.0, "s0": 12.5, "v": 27.78}])
def test_static_loads_keep_wheels_at_zero(c_fmu, start):
    path, _, _ = c_fmu
    m_body = start.get("m_body", 18500.0)
    load = -(m_body + 1500.0) * GRAVITY / 2          # downward +: the rail pushes up
    start_values = dict(start, **{"axle1.FL": load, "axle1.FR": load})
    res = simulate_fmu(str(path), start_time=0.0, stop_time=1.0, step_size=1e-3, output_interval=1e-3,
                       start_values=start_values, output=["axle1.s", *OUTPUTS])
    assert len(res) == 1001
    for name in OUTPUTS:
        assert np.abs(res[name]).max() <= 1e-12, name
    s_expected = start.get("s0", 0.0) + start.get("v", 33.333) * res["time"]
    np.testing.assert_allclose(res["axle1.s"], s_expected, rtol=1e-14, atol=1e-12)


# ------------------------------------------------------------------- dynamics
# FMU parameter -> QuarterParams field (the sprung mass follows from axle_load, see below)
OTHER_PARAMETERS = {"m_body": 24000.0, "m_axle": 1800.0, "J_body": 2.6e4, "J_axle": 850.0,
                    "k_prim": 0.9e6, "c_prim": 1.5e4, "b_prim": 1.05, "b_wheel": 0.7465}


def quarter_params(fmu_params: dict) -> QuarterParams:
    p = {**{"m_body": 18500.0, "m_axle": 1500.0}, **fmu_params}
    mapping = {"m_axle": "wheelset_mass", "J_body": "sprung_roll_inertia", "J_axle": "wheelset_roll_inertia",
               "k_prim": "k1", "c_prim": "c1", "b_prim": "b1", "b_wheel": "b0"}
    kw = {mapping[k]: v for k, v in p.items() if k in mapping}
    return QuarterParams(axle_load=(p["m_body"] + p["m_axle"]) * GRAVITY, flexible=False, **kw)


@pytest.mark.parametrize("history, steps, params", [
    ("left_step", "fixed", {}),
    ("doublet", "fixed", {}),
    ("left_step", "variable", {}),
    ("doublet", "variable", OTHER_PARAMETERS),
])
def test_matches_python_rigid_quarter_vehicle(c_fmu, history, steps, params):
    """C RK4 (sub-steps <= 1e-5 s) vs the exact zero-order-hold discretisation, after sign conversion."""
    n = 400
    hs = step_sizes(steps, n)
    qp = quarter_params(params)
    veh = quarter_vehicle(qp)
    static = veh.static_state([0.0, 0.0])          # ours: wheels at 0, like the C model
    load = qp.axle_load / 2                        # static load per wheel, upward +
    np.testing.assert_allclose(static.Fz, load, rtol=1e-12)
    Fz = force_history(history, n, 1e-3, load)     # per step, upward + (our convention)
    stepper = VehicleStepper(veh, None, q0=static.q, Fz0=static.Fz)

    inst = Instance(c_fmu, start=params)
    try:
        c_out = np.empty((n, 4))
        py_out = np.empty((n, 4))
        for k in range(n):
            inst.step(-Fz[k, 0], -Fz[k, 1], hs[k])              # our Fz = -FL
            stepper.set_step(hs[k])
            stepper.step(Fz[k])
            c_out[k] = -inst.get(*OUTPUTS)                      # our z = -zL, vz = -vzL
            py_out[k, :2] = stepper.wheel_z
            py_out[k, 2:] = stepper.wheel_vz
        t_end = hs.sum()
        assert inst.get("time")[0] == pytest.approx(t_end, rel=1e-14)
        assert inst.get("axle1.s")[0] == pytest.approx(33.333 * t_end, rel=1e-13)
    finally:
        inst.close()

    peak = np.abs(py_out).max(axis=0)                         # response from the static state (z = 0)
    assert np.all(peak > 1e-4)                                # the test excites every output
    err = np.abs(c_out - py_out).max(axis=0)
    assert np.all(err <= 1e-6 * peak), err / peak


# ------------------------------------------------------------------ FMU state
def run(inst, F, h=1e-3) -> np.ndarray:
    out = np.empty((len(F), 6))
    for k, (FL, FR) in enumerate(F):
        inst.step(FL, FR, h)
        out[k] = inst.get("time", "axle1.s", *OUTPUTS)
    return out


def test_fmu_state_round_trip_is_bit_identical(instance):
    F = -force_history("doublet", 200, 1e-3)                  # downward +
    run(instance, F[:50])
    state = instance.fmu.getFMUstate()
    t_saved, inputs_saved = instance.t, instance.get(*INPUTS)
    first = run(instance, F[50:])

    # a different excursion, then back
    run(instance, -F[50:120])
    instance.fmu.setFMUstate(state)
    np.testing.assert_array_equal(instance.get(*INPUTS), inputs_saved)   # inputs are part of the state
    instance.t = t_saved
    second = run(instance, F[50:])
    assert np.array_equal(first, second)

    # the same state again (a state may be set several times), then freed
    instance.fmu.setFMUstate(state)
    instance.t = t_saved
    assert np.array_equal(run(instance, F[50:]), first)
    instance.fmu.freeFMUstate(state)


def test_serialized_state_continues_in_another_instance(c_fmu, instance):
    F = -force_history("left_step", 150, 1e-3)
    run(instance, F[:60])
    state = instance.fmu.getFMUstate()
    blob = instance.fmu.serializeFMUstate(state)
    instance.fmu.freeFMUstate(state)
    t_saved = instance.t
    first = run(instance, F[60:])

    other = Instance(c_fmu, name="other")
    try:
        restored = other.fmu.deSerializeFMUstate(blob)
        other.fmu.setFMUstate(restored)
        other.fmu.freeFMUstate(restored)
        other.t = t_saved
        assert np.array_equal(run(other, F[60:]), first)
        with pytest.raises(FMICallException):
            other.fmu.deSerializeFMUstate(blob[:-1])           # truncated
    finally:
        other.close()


# --------------------------------------------------------------------- errors
def test_nan_input_is_an_error_and_state_recovers(instance):
    F = -force_history("doublet", 100, 1e-3)
    run(instance, F[:20])
    state = instance.fmu.getFMUstate()
    t_saved = instance.t
    reference = run(instance, F[20:40])

    instance.fmu.setFMUstate(state)
    instance.t = t_saved
    with pytest.raises(FMICallException) as exc:
        instance.set("axle1.FL", float("nan"))
    assert exc.value.status == 3                              # fmi2Error
    assert any(status == 3 and "axle1.FL" in msg and "not a finite number" in msg
               for status, msg in instance.messages), instance.messages
    with pytest.raises(FMICallException):                     # the instance is in the error state
        instance.fmu.doStep(instance.t, 1e-3)

    instance.fmu.setFMUstate(state)                           # the documented way back
    instance.t = t_saved
    assert np.array_equal(run(instance, F[20:40]), reference)
    instance.fmu.freeFMUstate(state)


@pytest.mark.parametrize("action, message", [
    (lambda i: i.set("m_body", 24000.0), "fixed after initialization"),
    (lambda i: i.fmu.doStep(i.t, 0.0), "communicationStepSize"),
    (lambda i: i.set("axle1.FR", float("inf")), "not a finite number"),
    (lambda i: i.fmu.getDirectionalDerivative([2], [6], [1.0]), "not supported"),
])
def test_illegal_calls_are_errors(instance, action, message):
    with pytest.raises(FMICallException):
        action(instance)
    assert any(status == 3 and message in msg for status, msg in instance.messages), instance.messages


def test_non_physical_parameter_is_refused(c_fmu):
    inst = Instance(c_fmu, start={"m_axle": -1.0}, initialize=False)
    try:
        inst.fmu.enterInitializationMode()
        with pytest.raises(FMICallException):
            inst.fmu.exitInitializationMode()
        assert any("m_axle must be positive" in msg for _, msg in inst.messages), inst.messages
    finally:
        inst.close()


def test_reset_restarts_from_the_static_state(c_fmu, instance):
    F = -force_history("left_step", 80, 1e-3)
    first = run(instance, F)
    instance.fmu.reset()
    assert instance.get("time", *OUTPUTS).tolist() == [0.0] * 5
    instance.t = 0.0
    instance.fmu.setupExperiment(startTime=0.0)
    instance.initialize()
    assert np.array_equal(run(instance, F), first)
