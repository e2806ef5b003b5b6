"""Vehicle FMU slaves: ``Bogie`` and ``QuarterVehicle`` (FMI 2.0 co-simulation, pythonfmu).

Ports (DESIGN §4.4), wheels i = 1..n: front wheelset left, right, then the next:

* inputs  ``wheel{i}_Fz`` [N]   vertical contact force on the wheel, upward +
* outputs ``wheel{i}_x`` [m]    track coordinate, ``x0 + a_i + speed * t``
          ``wheel{i}_z`` [m]    vertical displacement of the contact point, upward +
          ``wheel{i}_vz`` [m/s] its velocity
* parameters (variability "fixed": set them before exitInitializationMode, where the
  model is built): ``speed``, ``x0``, ``wheel{i}_z0`` and one per field of the
  model's parameter dataclass (``vehicle.BogieParams`` / ``vehicle.QuarterParams``).
* output, monitoring: ``python_steps`` (Integer), the steps taken in Python (below)

At exitInitializationMode the vehicle is placed in static equilibrium on the wheel
positions ``wheel{i}_z0``.  An input the host never set takes the static wheel load
of the actual parameters (its XML start value is that of the default parameters).
``doStep`` advances the model with the exact discretisation for forces held over the
step (``vehicle.VehicleStepper``, zero-order hold); a new step size re-discretises.
After the first step the instance registers that step with the FMU's C shim (``fmus.fast``:
its ``xpanel_lti_step``, ``y <- G [y | Fz | 1]`` and the wheels' x, z, vz, with the slave's own
arrays): the shim then takes the steps and the port reads and writes without entering Python, the
same algorithm, summed in index order where numpy's BLAS sums in an order of its own (round-off,
~1e-12 of the response). A step size change, a non-finite force or any other call goes to Python.

The slaves only map FMU variables onto the ``vehicle`` model objects.
"""
from __future__ import annotations

import ctypes
import dataclasses
from typing import Any, Dict

import numpy as np
from pythonfmu.default_experiment import DefaultExperiment

from .base import CosimSlave
from .fast import FastPath, LtiStep, fast_enabled, lti_step_address, shim_library

try:  # inside a built FMU the model package is bundled next to this module
    from . import vehicle as _vehicle
except ImportError as _exc:  # source tree: src/ on sys.path
    if isinstance(_exc, ModuleNotFoundError) and _exc.name not in (None, f"{__package__}.vehicle"):
        raise   # a dependency of the bundled package is missing (scipy, ...): say which
    import vehicle as _vehicle

DEFAULT_SPEED = 33.333   # m/s (120 km/h), as in the DESIGN example scenario
STEP_RTOL = 1e-12        # step sizes closer than this (relative) reuse the discretisation
SIDE = ("left", "right")


class VehicleSlave(CosimSlave):
    """Common slave of the vehicle FMUs; subclasses set the model and its parameters."""

    author = "crossing-panel co-simulation project"
    version = "0.1"
    default_experiment = DefaultExperiment(start_time=0.0, stop_time=1.0, step_size=1e-4)
    params_type: type = None           # parameter dataclass
    offset_parameters: tuple = ()      # dataclass fields the wheel offsets a_i depend on

    @staticmethod
    def build_model(params) -> "_vehicle.LinearVehicle":
        raise NotImplementedError

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        fields = dataclasses.fields(self.params_type)
        self._field_names = [f.name for f in fields]
        self._values: Dict[str, Any] = {"speed": DEFAULT_SPEED, "x0": 0.0}
        self._values.update({f.name: f.default for f in fields})
        preview = self.build_model(self.params_type())
        m = preview.n_wheels
        for i in range(m):
            self._values[f"wheel{i + 1}_z0"] = 0.0
        self._preview, self._preview_key = preview, self._key()
        # start values of the inputs: static loads of the default parameters, rounded to
        # 12 significant digits to drop the solver's last-digit noise from the XML
        self.Fz = np.array([float(f"{f:.12g}") for f in preview.static_state(np.zeros(m)).Fz])
        self._Fz_set = [False] * m
        self._stepper = None
        self._offsets = preview.wheel_offsets.copy()
        self._built_key = None
        self._time = 0.0
        self._fast = None          # FastPath once registered (after the first step); False: none here
        self._lti = LtiStep()      # the shim's step of the zoh system (filled by _fast_load)
        self._lti_arrays = ()      # the arrays it points into (kept alive)
        self._lti_stepper = None   # the stepper whose arrays those are
        self._time_buf = np.zeros(1)

        self.add_parameter("speed", "constant vehicle speed along increasing track coordinate x",
                           "m/s", *self._accessors("speed"))
        self.add_parameter("x0", "track coordinate of the front wheelset at t = 0", "m",
                           *self._accessors("x0"))
        for i in range(m):
            self.add_parameter(f"wheel{i + 1}_z0",
                               f"static vertical position of wheel {i + 1} ({self._label(i)}) "
                               "contact point, upward + (rail top under the static load)",
                               "m", *self._accessors(f"wheel{i + 1}_z0"))
        for f in fields:
            is_bool = isinstance(f.default, bool)
            self.add_parameter(f.name, f.metadata["doc"], f.metadata["unit"],
                               *self._accessors(f.name, bool if is_bool else float), boolean=is_bool)
        for i in range(m):
            self.add_input(f"wheel{i + 1}_Fz",
                           f"vertical contact force on wheel {i + 1} ({self._label(i)}), upward +; "
                           "if never set, the static wheel load of the actual parameters",
                           "N", lambda i=i: self.Fz[i], lambda value, i=i: self._set_force(i, value))
        x_deps = ("x0", "speed") + tuple(self.offset_parameters)
        for i in range(m):
            n = i + 1
            self.add_output(f"wheel{n}_x", f"track coordinate of wheel {n} ({self._label(i)})", "m",
                            lambda i=i: self._wheel_x(i), x_deps)
            self.add_output(f"wheel{n}_z", f"vertical displacement of wheel {n} ({self._label(i)}) "
                            "contact point, upward +", "m", lambda i=i: self._wheel_z(i),
                            (f"wheel{n}_z0",))
            self.add_output(f"wheel{n}_vz", f"vertical velocity of wheel {n} ({self._label(i)}), "
                            "upward +", "m/s", lambda i=i: self._wheel_vz(i))
        self._add_python_steps_output()
        self.apply_baked_start_values()   # the scenario's x0, speed, ... (fmus.build, start_values)

    # ---------------------------------------------------------------- mapping
    @staticmethod
    def _label(i: int) -> str:
        return f"wheelset {i // 2 + 1} {SIDE[i % 2]}"

    def _key(self) -> tuple:
        return tuple(self._values[name] for name in self._field_names)

    def _accessors(self, name: str, cast=float):
        def get():
            return self._values[name]

        def set_(value):
            if self._stepper is not None and not self._restoring:
                self.log_warning(f"parameter {name} is fixed after initialization: "
                                 f"new value {value!r} ignored")
                return
            self._values[name] = cast(value)
        return get, set_

    def _set_force(self, i: int, value: float) -> None:
        self.Fz[i] = value
        self._Fz_set[i] = True

    def _params(self):
        return self.params_type(**{name: self._values[name] for name in self._field_names})

    def _wheel_x(self, i: int) -> float:
        if self._stepper is None and self._key() != self._preview_key:
            try:  # initialization mode: wheel offsets follow the current parameter values
                self._preview = self.build_model(self._params())
            except Exception:
                pass  # invalid values are reported at exitInitializationMode
            self._preview_key = self._key()
            self._offsets = self._preview.wheel_offsets.copy()
        t = self._time if self._stepper is not None else self.start_time
        return self._values["x0"] + self._offsets[i] + self._values["speed"] * t

    def _wheel_z(self, i: int) -> float:
        if self._stepper is None:
            return self._values[f"wheel{i + 1}_z0"]
        return self._stepper.wheel_z[i]

    def _wheel_vz(self, i: int) -> float:
        return 0.0 if self._stepper is None else self._stepper.wheel_vz[i]

    def _wheel_z0(self) -> np.ndarray:
        return np.array([self._values[f"wheel{i + 1}_z0"] for i in range(len(self.Fz))])

    # -------------------------------------------------------------- lifecycle
    def initialize_model(self) -> None:
        self._build(self._wheel_z0())
        self._time = self.start_time
        self._python_steps = 0

    def _build(self, z0: np.ndarray | None) -> None:
        """Build model and stepper from the parameter values; ``z0``: place in static state."""
        model = self.build_model(self._params())
        stepper = _vehicle.VehicleStepper(model, None, "zoh")
        if z0 is not None:
            static = model.static_state(z0)
            for i, was_set in enumerate(self._Fz_set):
                if not was_set:
                    self.Fz[i] = static.Fz[i]
            mismatch = np.max(np.abs(self.Fz - static.Fz))
            if mismatch > 1e-6 * np.max(np.abs(static.Fz)):
                self.log_warning(f"input forces differ from the static wheel loads "
                                 f"{static.Fz.tolist()} N by up to {mismatch:.6g} N: "
                                 "the vehicle starts with a transient")
            stepper.reset(static.q, None, self.Fz)
        self._stepper, self._built_key = stepper, self._key()
        self._offsets = model.wheel_offsets.copy()

    def advance(self, current_time: float, step_size: float) -> None:
        stepper = self._stepper
        if stepper.h is None or abs(step_size - stepper.h) > STEP_RTOL * stepper.h:
            stepper.set_step(step_size)
        stepper.step(self.Fz)
        self._time = current_time + step_size
        self._stepped_in_python()

    # -------------------------------------------------------------- fast path (fmus.fast)
    def _register_fast(self) -> None:
        """Register the shim's step of a linear discrete-time system (``xpanel_lti_step``) for the
        exact zoh step, where the FMU has the shim; the wheels' x, z, vz then come from it."""
        self._fast = False
        lib = shim_library(self.resources) if fast_enabled() else None
        if lib is None or self._stepper.hold != "zoh":
            return
        m = len(self.Fz)
        vr = {v.name: v.value_reference for v in self.vars.values()}
        outs = [vr[f"wheel{i + 1}_{k}"] for k in ("x", "z", "vz") for i in range(m)]
        fast = FastPath(lib, lti_step_address(lib), [vr[f"wheel{i + 1}_Fz"] for i in range(m)], self.Fz,
                        outs, np.zeros(3 * m), self._fast_load, self._fast_sync)
        if fast.register(ctypes.addressof(self._lti)):
            self._fast = fast

    def _fast_load(self, current: bool) -> bool:
        """The shim's ``load``: its step's data from the stepper (see fmus.fast.FastPath)."""
        st = self._stepper
        if self._failure is not None or st is None or st.hold != "zoh" or st.h is None:
            return False
        if current:
            return True
        m = len(self.Fz)
        G, z, _, _, ynew, Y_wheel, wheel, wheel_offset = st.discrete_system()
        G = np.ascontiguousarray(G, dtype=float)
        ny = ynew.size
        Y = np.zeros((3 * m, ny))
        Y[m:] = Y_wheel
        v = self._values
        off = np.concatenate([[v["x0"] + self._offsets[i] for i in range(m)], wheel_offset])
        tco = np.concatenate([np.full(m, float(v["speed"])), np.zeros(2 * m)])
        out = self._fast.out_buf
        out[:m] = [self._wheel_x(i) for i in range(m)]
        out[m:] = wheel
        self._time_buf[0] = self._time
        self._lti_stepper = st
        self._lti_arrays = (G, z, ynew, Y, off, tco, out, self.Fz, self._time_buf)
        a = [x.ctypes.data for x in self._lti_arrays]
        lti = self._lti
        lti.ny, lti.nz, lti.nout = ny, G.shape[1], 3 * m
        lti.G, lti.z, lti.ynew, lti.Y, lti.off, lti.tco, lti.out, lti.u_in, lti.time = a
        lti.h, lti.rtol, lti.steps = st.h, STEP_RTOL, 0
        return True

    def _fast_sync(self) -> None:
        """The shim's ``sync``: the steps' wheel outputs, time and count into the stepper."""
        st, m = self._stepper, len(self.Fz)
        if st is None or st is not self._lti_stepper:   # rebuilt since: the steps were the old stepper's
            return
        st.wheel_z[:], st.wheel_vz[:] = self._fast.out_buf[m:2 * m], self._fast.out_buf[2 * m:]
        self._time = float(self._time_buf[0])
        st.steps += int(self._lti.steps)
        self._lti.steps = 0

    # -------------------------------------------------------------- FMU state
    def get_internal_state(self) -> Dict[str, Any]:
        state = super().get_internal_state()
        state.update(time=self._time, Fz_set=list(self._Fz_set), initialized=self._stepper is not None)
        if self._stepper is not None:
            state.update(h=self._stepper.h, stepper=self._stepper.get_state())
        return state

    def set_internal_state(self, state: Dict[str, Any]) -> None:
        super().set_internal_state(state)
        self._time = float(state["time"])
        self._Fz_set = [bool(s) for s in state["Fz_set"]]
        if not state["initialized"]:
            self._stepper = None
            return
        if self._stepper is None or self._built_key != self._key():
            self._build(None)
        if state["h"] is not None:
            self._stepper.set_step(state["h"])
        self._stepper.set_state(state["stepper"])


class Bogie(VehicleSlave):
    """Bogie with half car-body mass, 4 wheels (vehicle.bogie)."""

    description = ("Bogie with half car-body mass (car body bounce/roll, frame bounce/pitch/roll, "
                   "two wheelsets bounce/roll); vertical dynamics, constant speed")
    params_type = _vehicle.BogieParams
    offset_parameters = ("wheelbase",)

    @staticmethod
    def build_model(params):
        return _vehicle.bogie(params)


class QuarterVehicle(VehicleSlave):
    """Quarter vehicle with an optionally flexible wheelset, 2 wheels (vehicle.quarter_vehicle)."""

    description = ("Quarter vehicle: sprung mass on the primary suspension of one wheelset "
                   "(optionally flexible: first symmetric bending mode); vertical dynamics")
    params_type = _vehicle.QuarterParams

    @staticmethod
    def build_model(params):
        return _vehicle.quarter_vehicle(params)
