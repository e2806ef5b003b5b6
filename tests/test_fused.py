"""The Gauss–Seidel loop in compiled blocks: in-process (track.fused) and over two FMUs
(orchestrator.cosim.compiled_loop.FmuLoop).

Consistency checks of two code paths of ours (not verification: the physics of both is the
stepped path's, verified elsewhere): the compiled loop must give the numbers, the errors, the
partial results and the objects' state that the master's one-call-a-time loop gives.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from orchestrator.cosim.compiled_loop import COMPILED_LOOP_ENV
from orchestrator.cosim.master import run_cosim
from orchestrator.inputs.scenario import load_scenario
from track.layout import build_layout

ROOT = Path(__file__).resolve().parents[1]
DEFAULT = ROOT / "scenarios" / "crossing_1_12_through_120.yaml"
SIGNALS = ("t", "x", "z", "vz", "Fz", "parts", "rail_z")
# Same operations in the same order in both paths; the vehicle's two matrix-vector products go
# through numpy's BLAS in one and through the BLAS numba calls (scipy's build) in the other, which
# may round a dgemv differently on another machine: 1e-9 relative covers that round-off grown over
# the run (here both paths agree to the last bit).
RTOL = 1e-9


def _crossing_scenario(duration: float = 0.06, extra: tuple = ()):
    """The default scenario, front wheelset 0.8 m before the crossing's theoretical point, at a
    step of 50 us with an output every 100 us (two steps per signal row)."""
    sc = load_scenario(DEFAULT)
    x_tcp = build_layout(sc.track.layout).x_tcp
    return load_scenario(DEFAULT, [f"simulation.x_start={x_tcp - 0.8}", f"simulation.duration={duration}",
                                   "simulation.step=5e-5", "simulation.output_step=1e-4", *extra])


def _spy(monkeypatch) -> list:
    """The runs a CompiledLoop is made for (so a test knows which loop ran)."""
    from orchestrator.cosim import compiled_loop as cl

    made, real = [], cl.CompiledLoop
    monkeypatch.setattr(cl, "CompiledLoop", lambda run: made.append(run) or real(run))
    return made


def _both(monkeypatch, sc, **kw):
    """The run stepped one call at a time, then with the compiled loop (which must have run)."""
    made = _spy(monkeypatch)
    out = {}
    for mode in ("0", "1"):
        monkeypatch.setenv(COMPILED_LOOP_ENV, mode)
        out[mode] = run_cosim(sc, backend="inprocess", **kw)
        assert len(made) == int(mode)
    return out["0"], out["1"]


def _assert_same(a, b) -> None:
    for k in SIGNALS:
        np.testing.assert_allclose(getattr(b, k), getattr(a, k), rtol=RTOL, atol=0.0, equal_nan=True, err_msg=k)
    assert (a.track_record is None) == (b.track_record is None)
    for k, v in (a.track_record or {}).items():
        np.testing.assert_allclose(b.track_record[k], v, rtol=RTOL, atol=1e-300, err_msg=f"record {k}")
    ca, cb = a.stats.counters, b.stats.counters
    for k in ("steps", "track_steps", "contact_iterations", "passes"):   # not the solves: the second run
        assert getattr(cb, k) == getattr(ca, k), k                        # reuses the first's influence rows
    assert cb.linear_solves >= cb.track_steps


@pytest.mark.parametrize("extra", [(), ("track.crossing.geometry=profiles", "vehicle.lateral_offset=0.003")])
def test_the_compiled_loop_gives_the_stepped_loops_numbers(monkeypatch, extra):
    """Through the crossing (the wheels enter new elements: the kernel returns to Python to load
    them and is resumed), two steps per output row, the sensor columns a diagnosis records:
    signals, record and counters as the one-call-a-time loop; with the crossing's dip and with the
    profile contact's tables at a constant lateral offset."""
    from orchestrator.cosim.sensing import sensor_columns
    from orchestrator.inputs.sensor_layout import layout_of, resolve
    from orchestrator.inputs.track_model import track_model
    from track.sensors import compile_sensors

    sc = _crossing_scenario(extra=extra)
    model = track_model(sc.track)
    cols = sensor_columns(model, compile_sensors(model, resolve(layout_of(sc), model)))
    a, b = _both(monkeypatch, sc, record_states=True, record_columns=cols)
    assert a.error is None and b.error is None
    assert a.Fz.shape == (601, 4) and a.Fz[:, 0].max() > 1.05 * a.Fz[1, 0]   # the impact is in the run
    _assert_same(a, b)


def test_the_compiled_loop_stops_where_the_stepped_loop_stops(monkeypatch):
    """A divergence (here: a limit of 1.03 static loads, which the crossing's impact passes) ends both
    loops at the same step with the same message, the same rows written and the same record."""
    import track.cosim

    monkeypatch.setattr(track.cosim, "DIVERGENCE_FACTOR", 1.03)
    a, b = _both(monkeypatch, _crossing_scenario(), record_states=True)
    assert a.error is not None and "diverged" in a.error
    assert b.error == a.error
    assert 10 < len(a.t) < 601
    _assert_same(a, b)


def test_the_compiled_loop_reports_progress_at_output_steps(monkeypatch):
    """progress(k, nsteps) between blocks: at output steps, increasing, the last at the run's end."""
    made = _spy(monkeypatch)
    monkeypatch.setenv(COMPILED_LOOP_ENV, "1")
    calls = []
    res = run_cosim(_crossing_scenario(0.12), backend="inprocess", record_states=False,
                    progress=lambda k, n: calls.append((k, n)))
    assert res.error is None
    ks = [k for k, _ in calls]
    assert ks == sorted(set(ks)) and all(k % 2 == 0 for k in ks) and len(ks) >= 3
    assert calls[-1] == (2400, 2400) and len(made) == 1


@pytest.mark.parametrize("override", ["track.irregularity.psd_wavenumber=[0.1, 10.0]",
                                      "simulation.algorithm=jacobi"])
def test_units_the_compiled_loop_cannot_step_run_one_call_at_a_time(monkeypatch, override):
    """Rail irregularities (evaluated in Python) and the Jacobi master keep the stepped loop."""
    made = _spy(monkeypatch)
    monkeypatch.setenv(COMPILED_LOOP_ENV, "1")
    over = [override] + (["track.irregularity.psd=[1e-7, 1e-11]"] if "psd" in override else [])
    sc = load_scenario(DEFAULT, over + ["simulation.duration=0.005"])
    assert run_cosim(sc, backend="inprocess", record_states=False).error is None
    assert made == []


# ------------------------------------------------------------------ the FMU loop (compiled_loop.FmuLoop)
@pytest.fixture(scope="module")
def crossing_fmus(tmp_path_factory):
    """The FMUs of _crossing_scenario (its track baked in), built once."""
    from orchestrator.cosim.build_job import build_fmus

    out = tmp_path_factory.mktemp("fused_fmus")
    build_fmus(_crossing_scenario(), out)
    return out


def _both_fmu(monkeypatch, sc, fmu_dir, **kw):
    """The FMU run stepped one call at a time, then with the compiled FMU loop (which must have run)."""
    from orchestrator.cosim import compiled_loop as cl

    made, real = [], cl.FmuLoop
    monkeypatch.setattr(cl, "FmuLoop", lambda run: made.append(run) or real(run))
    out = {}
    for mode in ("0", "1"):
        monkeypatch.setenv(COMPILED_LOOP_ENV, mode)
        out[mode] = run_cosim(sc, backend="fmu", fmu_dir=fmu_dir, **kw)
        assert len(made) == int(mode)
    return out["0"], out["1"]


def test_the_compiled_fmu_loop_gives_the_stepped_loops_numbers(monkeypatch, crossing_fmus):
    """Both units FMUs, through the crossing with a record of every output row: the compiled loop makes
    the stepped loop's fmi2 calls with the same values, so signals, record and counters are equal to
    the last bit (the same FMUs answer both)."""
    a, b = _both_fmu(monkeypatch, _crossing_scenario(), crossing_fmus, record_states=True)
    assert a.error is None and b.error is None
    assert a.Fz[:, 0].max() > 1.05 * a.Fz[1, 0]   # the impact is in the run
    for k in SIGNALS:
        assert np.array_equal(getattr(a, k), getattr(b, k), equal_nan=True), k
    assert a.track_record.keys() == b.track_record.keys()
    for k, v in a.track_record.items():
        assert np.array_equal(v, b.track_record[k]), k
    ca, cb = a.stats.counters, b.stats.counters
    for k in ("steps", "track_steps", "contact_iterations", "passes"):
        assert getattr(cb, k) == getattr(ca, k), k


def test_the_compiled_fmu_loop_stops_where_the_stepped_loop_stops(monkeypatch, crossing_fmus):
    """A divergence in the track FMU (its bundled track.cosim's limit lowered to 1.03 static loads, which
    the crossing's impact passes: the compiled step hands that step to Python, which discards it) ends
    both loops at the same step with the same message and the same rows written."""
    import sys

    sc = _crossing_scenario()
    run_cosim(load_scenario(DEFAULT, ["simulation.duration=0.001"]), backend="fmu", fmu_dir=crossing_fmus,
              record_states=False)                     # loads the FMU's bundled package
    bundled = [m for name, m in sys.modules.items() if name.startswith("xpanel_track_") and name.endswith(".cosim")]
    assert bundled
    for m in bundled:
        monkeypatch.setattr(m, "DIVERGENCE_FACTOR", 1.03)
    a, b = _both_fmu(monkeypatch, sc, crossing_fmus, record_states=False)
    assert a.error is not None and "fmi2DoStep" in a.error and "track FMU" in a.error
    assert b.error == a.error
    assert 10 < len(a.t) < 601 and len(b.t) == len(a.t)
    for k in SIGNALS:
        assert np.array_equal(getattr(a, k), getattr(b, k), equal_nan=True), k


def test_the_compiled_fmu_loop_reports_progress_at_output_steps(monkeypatch, crossing_fmus):
    """progress(k, nsteps) between the FMU loop's blocks: at output steps, increasing, the last at the end."""
    monkeypatch.setenv(COMPILED_LOOP_ENV, "1")
    calls = []
    res = run_cosim(_crossing_scenario(0.12), backend="fmu", fmu_dir=crossing_fmus, record_states=False,
                    progress=lambda k, n: calls.append((k, n)))
    assert res.error is None
    ks = [k for k, _ in calls]
    assert ks == sorted(set(ks)) and all(k % 2 == 0 for k in ks) and len(ks) >= 3
    assert calls[-1] == (2400, 2400)
