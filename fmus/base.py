"""``CosimSlave``: a thin layer over ``pythonfmu.Fmi2Slave`` that fixes its weak points.

What pythonfmu 0.7 does, and what this class changes (names are pythonfmu's):

(a) ``Fmi2Slave.to_xml`` writes ``<ModelStructure><Outputs>`` without ``dependencies``
    and no ``<InitialUnknowns>``, so ``fmpy.validation.validate_fmu`` fails.
    :meth:`CosimSlave.to_xml` calls it, then replaces ``ModelStructure`` with
    ``Outputs`` (``dependencies=""``: at a communication point the outputs are
    functions of the internal state only, no direct feed-through of inputs) and
    ``InitialUnknowns`` (every output, with the parameters it depends on in
    initialization mode, declared when the output is registered).  It also adds
    ``unit`` attributes with ``<UnitDefinitions>`` and the capability flags
    ``canGetAndSetFMUstate`` / ``canSerializeFMUstate``.
(b) The C wrapper's ``fmi2GetFMUstate`` stores whatever ``_get_fmu_state()``
    returns (a Python object, kept alive by the wrapper) and ``fmi2SetFMUstate``
    passes it back to ``_set_fmu_state(state)``; serialisation goes through the
    static methods ``_fmu_state_to_bytes`` / ``_fmu_state_from_bytes`` (called on
    the class).  pythonfmu's defaults save the registered variables only, as JSON.
    Here the state is ``{"variables": parameters and inputs, "internal":
    get_internal_state()}``, where subclasses return copies of their numpy arrays,
    counters and time; the byte form is JSON with arrays as lists (Python's float
    repr round-trips exactly, so a serialised state restores bit-identically).
(c) The wrapper maps ``do_step`` returning ``False`` to ``fmi2Discard`` and any
    Python exception to ``fmi2Fatal`` *after freeing the Python instance* (later
    calls would touch a dead object).  So nothing here raises: :meth:`do_step`
    rejects non-finite inputs or step sizes and model failures with ``False``
    (fmi2Discard, the state stays at the current communication point) and a log
    message with status fmi2Error; :meth:`exit_initialization_mode` records a
    failure (e.g. invalid parameters) and every later ``do_step`` is discarded
    with that message.  Log messages also go to the Python logger
    ``fmus.<ClassName>``, because the wrapper forwards them to the host only when
    the host instantiated the FMU with ``loggingOn=True``.
(d) pythonfmu variables have no unit field: the ``add_*`` helpers require a unit
    and append it to the description (``"... upward + [N]"``), besides (a).
(e) Module names: pythonfmu FMUs run in the host's interpreter and share
    ``sys.modules``; ``fmus.build`` bundles each FMU's code under a unique package
    name.  Modules used by slaves must therefore import their model package
    relatively when bundled (see ``fmus/vehicle_fmus.py``).

(f) Standalone defaults: ``fmus.build`` may bake ``resources/default_experiment.json``
    (the scenario's duration and step: :meth:`CosimSlave.to_xml` writes it as the
    ``DefaultExperiment``) and ``resources/start_values.json`` (parameter start values by
    name, e.g. the vehicle's ``x0`` and ``speed``: :meth:`apply_baked_start_values`, called
    by subclasses at the end of ``__init__``).
(g) A non-finite value for a Real parameter is refused when it is set (the previous value
    stays, so no output turns NaN) and logged with status fmi2Error; the instance then
    fails its initialization with that message and discards every ``doStep``, until a
    finite value replaces it before exitInitializationMode.  (pythonfmu gives setters no
    status to return, and raising would be fmi2Fatal.)
(h) Per-step cost: pythonfmu's ``get_real`` / ``set_real`` look every reference up and test
    its type on each call; here the Real variables are indexed once at registration
    (:meth:`get_real`, :meth:`set_real`; a reference that is not a Real variable, or a Real
    without a setter, takes pythonfmu's own path and its error), and ``do_step`` tests its
    inputs' finiteness with one sum (an infinite or NaN input makes it non-finite; a finite
    sum that overflows falls through to the per-input test, which then finds nothing).

Subclass contract: register variables with :meth:`add_parameter`,
:meth:`add_input`, :meth:`add_output` in ``__init__``; implement
:meth:`initialize_model` (called at exitInitializationMode) and :meth:`advance`
(one communication step); override :meth:`get_internal_state` /
:meth:`set_internal_state` for everything that evolves.
"""
from __future__ import annotations

import json
import logging
import math
from abc import abstractmethod
from pathlib import Path
from typing import Any, Callable, Dict, Iterable, Optional
from xml.etree.ElementTree import Element, SubElement

import numpy as np
from pythonfmu import Fmi2Slave
from pythonfmu.enums import Fmi2Causality, Fmi2Status, Fmi2Variability
from pythonfmu.variables import Boolean, Real

EXPERIMENT_FILE = "default_experiment.json"   # in resources/: {"startTime", "stopTime", "stepSize"} [s]
START_VALUES_FILE = "start_values.json"        # in resources/: {parameter name: start value}

# SI base-unit exponents of the units used in variable descriptions ("-" = dimensionless)
UNITS: Dict[str, Dict[str, int]] = {
    "m": {"m": 1},
    "m/s": {"m": 1, "s": -1},
    "s": {"s": 1},
    "Hz": {"s": -1},
    "rad": {"rad": 1},
    "kg": {"kg": 1},
    "kg.m2": {"kg": 1, "m": 2},
    "N": {"kg": 1, "m": 1, "s": -2},
    "N/m": {"kg": 1, "s": -2},
    "N.s/m": {"kg": 1, "s": -1},
    "Pa": {"kg": 1, "m": -1, "s": -2},
    "-": {},
}


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return {"__ndarray__": obj.tolist(), "dtype": str(obj.dtype), "shape": list(obj.shape)}
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f"FMU state entry of type {type(obj).__name__} is not serialisable")


def _json_object_hook(d: Dict[str, Any]) -> Any:
    if "__ndarray__" in d:
        return np.array(d["__ndarray__"], dtype=d["dtype"]).reshape(d["shape"])
    return d


class CosimSlave(Fmi2Slave):
    """Base class of this project's co-simulation slaves (see module docstring)."""

    _fast = False   # compiled steps through the shim (fmus.fast): a subclass that has them sets None in
    #                 __init__ (not registered yet) and implements _register_fast

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._units: Dict[str, str] = {}
        self._initial_dependencies: Dict[str, tuple] = {}
        self._real_inputs: list = []          # (name, getter) for the finiteness check
        self._real_getters: Dict[int, Callable[[], Any]] = {}   # value reference -> getter, (h)
        self._real_setters: Dict[int, Callable[[Any], None]] = {}
        self._failure: Optional[str] = None   # set when initialisation failed
        self._restoring = False               # True while _set_fmu_state restores variables
        self._rejected: Dict[str, str] = {}   # parameter name -> why its last value was refused
        self.start_time = 0.0
        self.pylog = logging.getLogger(f"fmus.{type(self).__name__}")

    # ------------------------------------------------------------ registration
    def _register(self, var, unit: str) -> None:
        if unit not in UNITS:
            raise ValueError(f"unknown unit {unit!r} for {var.name}; add it to fmus.base.UNITS")
        self._units[var.name] = unit
        self.register_variable(var, nested=False)
        if isinstance(var, Real):
            self._real_getters[var.value_reference] = var.getter
            if var.setter is not None:
                self._real_setters[var.value_reference] = var.setter

    def _add_python_steps_output(self) -> None:
        """The Integer output ``python_steps``: communication steps taken in Python since initialization
        (``self._python_steps``, counted by the subclass); the others ran in the FMU's compiled step
        through its C shim (``fmus.fast``)."""
        from pythonfmu.variables import Integer

        self._python_steps = 0
        self._register(Integer("python_steps", causality=Fmi2Causality.output, variability=Fmi2Variability.discrete,
                               description=self._describe(
                                   "communication steps taken in Python since initialization; the others ran "
                                   "in the FMU's compiled step (fmus.fast), when the FMU has its C shim "
                                   "(monitoring)", "-"),
                               getter=lambda: int(self._python_steps)), "-")
        self._initial_dependencies["python_steps"] = ()

    def _stepped_in_python(self) -> None:
        """Count a step Python took and, after the first, register the subclass's compiled steps with the
        FMU's shim (``_register_fast``, which sets ``self._fast``: a ``fmus.fast.FastPath``, or False).
        A failure there is a warning, never a failed step: the step has been taken."""
        self._python_steps += 1
        if self._fast is None:
            try:
                self._register_fast()
            except Exception as exc:
                self._fast = False
                self.log_warning(f"compiled steps unavailable, stepping in Python: {type(exc).__name__}: {exc}")

    def get_real(self, vrs):
        """Values of the Real variables ``vrs`` (module docstring, (h))."""
        getters = self._real_getters
        try:
            return [float(getters[vr]()) for vr in vrs]
        except KeyError:
            return super().get_real(vrs)

    def set_real(self, vrs, values):
        """Set the Real variables ``vrs`` (module docstring, (h))."""
        setters = self._real_setters
        if all(vr in setters for vr in vrs):
            for vr, value in zip(vrs, values):
                setters[vr](value)
        else:
            super().set_real(vrs, values)

    @staticmethod
    def _describe(description: str, unit: str) -> str:
        return f"{description} [{unit}]"

    def add_parameter(self, name: str, description: str, unit: str, getter: Callable[[], Any],
                      setter: Callable[[Any], None], tunable: bool = False, boolean: bool = False) -> None:
        """Register a parameter (variability ``fixed`` unless ``tunable``)."""
        variability = Fmi2Variability.tunable if tunable else Fmi2Variability.fixed
        cls = Boolean if boolean else Real
        if not boolean:
            setter = self._finite_setter(name, setter)
        self._register(cls(name, causality=Fmi2Causality.parameter, variability=variability,
                           description=self._describe(description, unit), getter=getter,
                           setter=setter), unit)

    def _finite_setter(self, name: str, setter: Callable[[Any], None]) -> Callable[[Any], None]:
        """``setter`` refusing non-finite values (module docstring, (g))."""
        def set_(value):
            if not math.isfinite(value):
                self._rejected[name] = f"parameter {name} = {float(value)!r} is not finite"
                self.log_error(f"{self._rejected[name]}: refused, {name} keeps its value; "
                               "initialization will fail unless a finite value is set")
                return
            self._rejected.pop(name, None)
            setter(value)
        return set_

    def apply_baked_start_values(self) -> None:
        """Set the parameters named in ``resources/start_values.json`` (if present)."""
        if self.resources is None or not (Path(self.resources) / START_VALUES_FILE).is_file():
            return
        values = json.loads((Path(self.resources) / START_VALUES_FILE).read_text(encoding="utf-8"))
        by_name = {v.name: v for v in self.vars.values()}
        unknown = sorted(set(values) - {n for n, v in by_name.items()
                                        if v.causality == Fmi2Causality.parameter})
        if unknown:
            raise ValueError(f"{START_VALUES_FILE}: {unknown} are not parameters of {type(self).__name__}")
        for name, value in values.items():
            by_name[name].setter(value)

    def add_input(self, name: str, description: str, unit: str, getter: Callable[[], float],
                  setter: Callable[[float], None]) -> None:
        """Register a continuous Real input; non-finite values make ``do_step`` discard."""
        self._register(Real(name, causality=Fmi2Causality.input,
                            variability=Fmi2Variability.continuous,
                            description=self._describe(description, unit), getter=getter,
                            setter=setter), unit)
        self._real_inputs.append((name, getter))

    def add_output(self, name: str, description: str, unit: str, getter: Callable[[], float],
                   initial_depends_on: Iterable[str] = ()) -> None:
        """Register a continuous Real output (initial="calculated").

        ``initial_depends_on`` names the parameters/inputs its value depends on in
        initialization mode (``InitialUnknowns`` dependencies).
        """
        self._register(Real(name, causality=Fmi2Causality.output,
                            variability=Fmi2Variability.continuous,
                            description=self._describe(description, unit), getter=getter), unit)
        self._initial_dependencies[name] = tuple(initial_depends_on)

    # --------------------------------------------------------------------- XML
    def to_xml(self, model_options: Optional[Dict[str, str]] = None) -> Element:
        options = {"canGetAndSetFMUstate": True, "canSerializeFMUstate": True}
        options.update(model_options or {})
        root = super().to_xml(options)
        self._add_default_experiment(root)
        self._add_units(root)
        self._replace_model_structure(root)
        return root

    def _add_default_experiment(self, root: Element) -> None:
        """Replace ``DefaultExperiment`` by the baked ``resources/default_experiment.json``."""
        if self.resources is None or not (Path(self.resources) / EXPERIMENT_FILE).is_file():
            return
        values = json.loads((Path(self.resources) / EXPERIMENT_FILE).read_text(encoding="utf-8"))
        node = root.find("DefaultExperiment")
        if node is None:   # schema order: ... LogCategories, DefaultExperiment, VendorAnnotations, ...
            node = Element("DefaultExperiment")
            root.insert(list(root).index(root.find("ModelVariables")), node)
        node.attrib.clear()
        node.attrib.update({k: repr(float(v)) for k, v in values.items()})

    def _add_units(self, root: Element) -> None:
        used = sorted({u for u in self._units.values() if u != "-"})
        if used:
            unit_defs = Element("UnitDefinitions")
            for u in used:
                unit = SubElement(unit_defs, "Unit", {"name": u})
                SubElement(unit, "BaseUnit", {k: str(v) for k, v in UNITS[u].items()})
            # schema order: CoSimulation, UnitDefinitions, TypeDefinitions, LogCategories, ...
            position = list(root).index(root.find("CoSimulation")) + 1
            root.insert(position, unit_defs)
        for sv in root.find("ModelVariables"):
            unit = self._units.get(sv.get("name"), "-")
            real = sv.find("Real")
            if real is not None and unit != "-":
                real.set("unit", unit)

    def _replace_model_structure(self, root: Element) -> None:
        old = root.find("ModelStructure")
        if old is not None:
            root.remove(old)
        structure = SubElement(root, "ModelStructure")
        index = {v.name: vr + 1 for vr, v in self.vars.items()}  # XML order == registration order
        outputs = [v for v in self.vars.values() if v.causality == Fmi2Causality.output]
        if outputs:
            node = SubElement(structure, "Outputs")
            for v in outputs:
                SubElement(node, "Unknown", {"index": str(index[v.name]), "dependencies": ""})
            node = SubElement(structure, "InitialUnknowns")
            for v in sorted(outputs, key=lambda v: index[v.name]):
                deps = sorted(index[name] for name in self._initial_dependencies.get(v.name, ()))
                SubElement(node, "Unknown", {"index": str(index[v.name]),
                                             "dependencies": " ".join(map(str, deps))})

    # --------------------------------------------------------------- lifecycle
    def setup_experiment(self, start_time: float, stop_time: Optional[float] = None,
                         tolerance: Optional[float] = None):
        self.start_time = float(start_time)

    def exit_initialization_mode(self):
        if self._rejected:
            self._failure = "initialization failed: " + "; ".join(self._rejected.values())
            self.log_error(self._failure)
            return
        try:
            self.initialize_model()
        except Exception as exc:  # never raise into pythonfmu (it would free the instance)
            self._failure = f"initialization failed: {type(exc).__name__}: {exc}"
            self.log_error(self._failure)

    def do_step(self, current_time: float, step_size: float) -> bool:
        if self._failure is not None:
            self.log_error(f"doStep at t = {current_time!r} discarded: {self._failure}")
            return False
        if not (math.isfinite(step_size) and step_size > 0.0):
            self.log_error(f"doStep at t = {current_time!r} discarded: step size {step_size!r} "
                           "is not positive and finite")
            return False
        if not math.isfinite(sum([g() for _, g in self._real_inputs])):
            bad = ", ".join(f"{n} = {float(g())!r}" for n, g in self._real_inputs if not math.isfinite(g()))
            if bad:
                self.log_error(f"doStep at t = {current_time!r} discarded: non-finite input {bad}; "
                               "the state stays at the current communication point")
                return False
        try:
            self.advance(current_time, step_size)
        except Exception as exc:
            self.log_error(f"doStep at t = {current_time!r} discarded: {type(exc).__name__}: {exc}")
            return False
        return True

    def log_error(self, message: str) -> None:
        """Log with status fmi2Error to the FMU logger and the Python logger."""
        self.log(message, Fmi2Status.error)
        self.pylog.error("%s: %s", self.instance_name, message)

    def log_warning(self, message: str) -> None:
        """Log with status fmi2Warning to the FMU logger and the Python logger."""
        self.log(message, Fmi2Status.warning)
        self.pylog.warning("%s: %s", self.instance_name, message)

    @abstractmethod
    def initialize_model(self) -> None:
        """Build the model from the parameter values (exitInitializationMode)."""

    @abstractmethod
    def advance(self, current_time: float, step_size: float) -> None:
        """Advance the model from ``current_time`` by ``step_size`` [s]; may raise."""

    # --------------------------------------------------------------- FMU state
    def get_internal_state(self) -> Dict[str, Any]:
        """Copies of everything that evolves (arrays, counters, time); JSON-able or ndarray."""
        return {"start_time": self.start_time, "failure": self._failure}

    def set_internal_state(self, state: Dict[str, Any]) -> None:
        """Restore from :meth:`get_internal_state` (copy, do not alias, the arrays)."""
        self.start_time = float(state["start_time"])
        self._failure = state["failure"]

    def _get_fmu_state(self) -> Dict[str, Any]:
        variables = {v.name: v.getter() for v in self.vars.values()
                     if v.setter is not None
                     and v.causality in (Fmi2Causality.parameter, Fmi2Causality.input)}
        return {"variables": variables, "internal": self.get_internal_state()}

    def _set_fmu_state(self, state: Dict[str, Any]) -> None:
        by_name = {v.name: v for v in self.vars.values()}
        self._restoring = True
        try:
            for name, value in state["variables"].items():
                by_name[name].setter(value)
            self._restoring = False
            self.set_internal_state(state["internal"])
        except Exception as exc:  # never raise into pythonfmu (it would free the instance)
            self._failure = f"FMU state could not be restored: {type(exc).__name__}: {exc}"
            self.log_error(self._failure)
        finally:
            self._restoring = False

    @staticmethod
    def _fmu_state_to_bytes(state: Dict[str, Any]) -> bytes:
        return json.dumps(state, default=_json_default).encode("utf-8")

    @staticmethod
    def _fmu_state_from_bytes(state: bytes) -> Dict[str, Any]:
        return json.loads(state.decode("utf-8"), object_hook=_json_object_hook)
