"""Jobs behind the command line: each takes a loaded Scenario and an output folder.

``run_scenario`` runs the co-simulation (:mod:`orchestrator.cosim.master`) and
post-processes the recorded track states with the same track model: contact
forces, wheel and rail displacements, bending-moment envelopes along the crossing
rail and the transition sleeper, the instants of maximum moment, ballast pressure.
"""
from __future__ import annotations

import json
import platform
import sys
import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from orchestrator.cosim.master import merge_columns
from orchestrator.cosim.sensing import read_sensors, sensor_columns
from orchestrator.inputs.errors import UserInputError
from orchestrator.inputs.track_model import track_model
from orchestrator.results import plots, run_figures
from orchestrator.results.analysis import analyse, analysis_columns, profile_contact
from orchestrator.results.figure_writer import FigureWriter
from orchestrator.results.outdir import prepare_out_dir
from track.frf import receptance
from track.kernel import warm_up_in_background
from track.model import reference_point
from track.statics import static_equilibrium
from track.timegrid import step_count

FRF_POINTS = 400          # frequencies of a receptance curve
FRF_FMIN = 5.0            # Hz
STATE_KEYS = ("t", "q", "v", "a")   # what --save-states writes of the track record
# results.h5 outputs: gzip level 1 with byte shuffle. Measured on the default scenario's outputs
# (8.1 MB raw): lzf+shuffle 6.9 MB, gzip-1+shuffle 6.6 MB, gzip-4+shuffle 6.6 MB, gzip-4 alone 7.4 MB;
# writing takes 0.1 s. The states (--save-states, 209 MB of float64 q, v, a) are stored as they are:
# their mantissas are noise, lzf+shuffle saved 6 % and gzip-1+shuffle 11 % at 2.5x and 5x the write time.
H5_COMPRESSION = {"compression": "gzip", "compression_opts": 1, "shuffle": True}
H5_COMPRESS_MIN = 64      # elements: smaller datasets are stored as they are
# BLAS threads of run_scenario's process once the model is built: one, as the other core draws the figures
# (figure_writer). With OpenBLAS's two threads the default scenario's post-processing (small products on
# blocks of states) took 0.26 s instead of 0.10 s, and the figures beside it were slower (2026-11-27, RESULTS.md).
RUN_BLAS_THREADS = 1


def _progress_bar(enabled: bool, total: int, desc: str):
    if not enabled:
        return None, lambda: None
    from tqdm import tqdm
    bar = tqdm(total=total, desc=desc, unit="step", mininterval=0.5)
    state = {"k": 0}

    def update(k: int, n: int) -> None:
        if state["k"] == 0 and k > 0:
            # the first report follows the first step, which carries the kernel's loading (or compilation:
            # seconds); timed from the start, it made the bar's rate 0.34 step/s and its remaining time 4 h on the
            # profiles scenario. The rate and remaining time count from here; that step is counted.
            bar.reset(total)
        bar.update(k - state["k"])
        state["k"] = k

    return update, bar.close


def run_scenario(scenario, out_dir: Path, progress: bool = True, backend: str = "fmu",
                 save_states: bool = False) -> dict:
    """Co-simulation of ``scenario``; writes sensors.csv, results.h5, summary.json and plots.

    The track records only the columns of its states that the post-processing reads
    (:func:`orchestrator.results.analysis.analysis_columns`,
    :func:`orchestrator.cosim.sensing.sensor_columns`; all of them with ``save_states``);
    they are post-processed in memory (virtual sensors by
    :func:`orchestrator.cosim.sensing.read_sensors`, moment envelopes and ballast pressure by
    :func:`orchestrator.results.analysis.analyse`) and then dropped: ``results.h5`` holds
    them (``track/q``, ``v``, ``a``) only with ``save_states``. The track FMU's record file
    never stays on disk (:func:`orchestrator.cosim.master.run_cosim`).

    Returns the summary dict (also written as summary.json). If the run stops early
    (divergence, a failing FMU) everything computed so far is written first and a
    :class:`UserInputError` names the cause.
    """
    t_start = time.perf_counter()
    warm_up_in_background()   # numba's one-time set-up beside the run's (track.kernel)
    with FigureWriter() as figures:   # first: its process imports matplotlib while the co-simulation runs
        out_dir = prepare_out_dir(out_dir)   # warns when it held an earlier run's results
        model = track_model(scenario.track)   # the model the run builds (its bodies cached) for the post-processing
        figures.submit("layout.png", run_figures.layout, out_dir, model.layout)   # drawn during the co-simulation
        with threadpool_limits(limits=RUN_BLAS_THREADS):   # the other core is the figure process's
            compiled = _compiled_sensors(scenario, model)
            columns = None if save_states else merge_columns(analysis_columns(model), sensor_columns(model, compiled))
            res = _cosimulate(scenario, out_dir, progress, backend, columns)
            t_post = time.perf_counter()
            sig = run_figures.plotted_signals(res)   # drawn while the main process post-processes
            figures.submit("contact_forces.png", run_figures.contact_forces, out_dir, scenario.name, sig)
            figures.submit("displacements.png", run_figures.displacements, out_dir, scenario.name, sig)
            summary, sensors, an, geometry = _post_process(scenario, backend, model, compiled, res)
            states = _states_to_save(res.track_record) if save_states else None
            res.track_record = None  # post-processed: what is not asked for is not kept
            t_write = time.perf_counter()
            _submit_analysis_figures(figures, out_dir, scenario.name, model.layout, sig, an, geometry)
            # ---- signals first: nothing computed is lost if a later step fails
            _write_signals(out_dir, res, sensors)
            _write_h5(out_dir / "results.h5", res, sensors, an, states, geometry)
            del states
            failed = figures.close()
    t_end = time.perf_counter()
    if failed:
        summary["figures_failed"] = failed
        for line in failed:
            print(f"warning: figure {line}", file=sys.stderr)
    summary["wall_seconds"]["job_total"] = t_end - t_start
    summary["counters"] = _counters(res, t_write - t_post, t_end - t_write)
    summary["counters"]["figure_process_peak_rss_mb"] = figures.peak_rss_mb   # None: drawn in this process
    summary["machine"] = f"{platform.machine()} {platform.system()} py{platform.python_version()}"
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2))
    if res.error:
        raise UserInputError(f"{res.error} (results up to t = {res.t[-1]:.4g} s written to {out_dir})")
    return summary


def _post_process(scenario, backend: str, model, compiled, res) -> tuple[dict, dict, object, dict | None]:
    """summary (head and contact), virtual sensors, the analysis and the profile contact geometry."""
    summary = _run_summary(scenario, backend, model, res)
    sensors = _virtual_sensors(scenario, model, compiled, res)
    Q0 = 0.5 * scenario.vehicle.axle_load
    summary["contact"] = _contact_summary(res, Q0)
    geometry = None
    if scenario.track.contact.geometry == "profiles":     # contact points, patches, emergent impact angle
        geometry, summary["contact"]["profiles"] = profile_contact(scenario.track.contact, model, res)
    an = analyse(model, Q0, res)
    summary.update(an.scalars)
    meta = getattr(an, "meta", None)
    if meta is not None:
        summary.update({"crossing_rail": meta["crossing_rail"], "transition_sleeper": meta["transition_sleeper"],
                        "crossing_side": meta["crossing_side"]})
    return summary, sensors, an, geometry


def _submit_analysis_figures(figures: FigureWriter, out_dir: Path, name: str, lay, sig, an,
                             geometry: dict | None) -> None:
    """Hand the figures of the analysis to ``figures`` (drawn while the main process writes the results)."""
    if getattr(an, "meta", None) is not None:
        figures.submit("envelopes.png, moments.png", run_figures.track_results, out_dir, name,
                       *run_figures.plotted_analysis(an))
    if geometry is not None and lay.x_tcp is not None:
        figures.submit("contact_path.png", run_figures.contact_path, out_dir, lay, sig, geometry)


def _cosimulate(scenario, out_dir: Path, progress: bool, backend: str, record_columns: dict | None = None):
    """Run the co-simulation (work folder ``out_dir/work``), recording ``record_columns`` of the track
    states (``None``: all), with a progress bar; returns its result."""
    from orchestrator.cosim.master import run_cosim

    sim = scenario.simulation
    nsteps = step_count(sim.duration, sim.step)
    update, close = _progress_bar(progress, nsteps, "co-simulation")
    try:
        return run_cosim(scenario, backend=backend, work_dir=out_dir / "work", progress=update,
                         record_columns=record_columns)
    finally:
        close()


def _run_summary(scenario, backend: str, model, res) -> dict:
    """The head of summary.json: scenario, vehicle, time grid, model size, wall times, error."""
    sim = scenario.simulation
    return {
        "scenario": scenario.name, "backend": backend, "algorithm": sim.algorithm,
        "vehicle": scenario.vehicle.fmu, "speed": scenario.vehicle.speed, "axle_load": scenario.vehicle.axle_load,
        "duration": float(res.t[-1]), "step": sim.step, "steps": res.stats["steps"],
        "dofs": {"reduced": model.n, "full": model.stats.fom_dofs, "bodies": model.stats.bodies},
        "wall_seconds": res.stats, "error": res.error,
    }


def _counters(res, wall_post: float, wall_write: float) -> dict:
    """summary.json's ``counters``: the run's :class:`orchestrator.cosim.stats.RunCounters` (``None``
    where the backend does not measure them: the track FMU's own counters) plus this job's
    post-processing and writing wall times [s]."""
    counters = getattr(res.stats, "counters", None)
    out = counters.to_json() if counters is not None else {}
    out.update(wall_post_processing=wall_post, wall_writing=wall_write)
    return out


def _contact_summary(res, Q0: float) -> dict:
    """wheel<i> -> max and min contact force and ΔQ = max - ``Q0`` [N] (``Q0`` the static wheel load)."""
    return {f"wheel{i + 1}": {"max_Fz": float(np.nanmax(res.Fz[:, i])),
                              "min_Fz": float(np.nanmin(res.Fz[:, i])),
                              "delta_Q": float(np.nanmax(res.Fz[:, i]) - Q0)} for i in range(res.Fz.shape[1])}


def _states_to_save(rec: dict | None) -> dict | None:
    """The recorded states ``--save-states`` writes: time [s] and the reduced coordinates ``q`` [m, rad],
    their rates ``v`` and accelerations ``a`` (the sensors read ``a``); the full field is ``u = T q``."""
    if rec is None or not len(rec.get("t", ())):
        return None
    return {k: rec[k] for k in STATE_KEYS if k in rec}


def _compiled_sensors(scenario, model):
    """The scenario's sensor layout (DESIGN.md §4.3) compiled on ``model`` (none on a track it does not fit)."""
    from orchestrator.inputs.sensor_layout import scenario_sensors
    from track.sensors import compile_sensors

    return compile_sensors(model, scenario_sensors(scenario, model))


def _virtual_sensors(scenario, model, compiled, res) -> dict:
    """The sensors' signals at the output times (:func:`orchestrator.cosim.sensing.read_sensors`);
    {} without sensors or a track record."""
    from orchestrator.inputs.sensor_layout import layout_of

    rec = res.track_record
    if not compiled.sensors or rec is None or "a" not in rec or len(rec["t"]) < 2 or len(rec["t"]) != len(res.t):
        return {}
    dt = float(np.median(np.diff(rec["t"])))
    return read_sensors(model, compiled, rec, dt, layout_of(scenario).displacement_highpass)


def _write_signals(out_dir: Path, res, sensors: dict) -> None:
    """sensors.csv: time, the layout's sensors and the monitoring signals of every wheel (SI units)."""
    cols = {"time": res.t, **sensors}
    for i in range(res.Fz.shape[1]):
        n = i + 1
        cols[f"wheel{n}_Fz"] = res.Fz[:, i]
        cols[f"wheel{n}_Fz_rail"] = res.parts[:, i, 0]
        cols[f"wheel{n}_Fz_nose"] = res.parts[:, i, 1]
        cols[f"wheel{n}_z"] = res.z[:, i]
        cols[f"wheel{n}_rail_z"] = res.rail_z[:, i]
        cols[f"wheel{n}_x"] = res.x[:, i]
    np.savetxt(out_dir / "sensors.csv", np.column_stack(list(cols.values())), delimiter=",",
               header=",".join(cols), comments="", fmt="%.9g")


def _put(group, name: str, data, compress: bool = True) -> None:
    """One dataset, compressed (:data:`H5_COMPRESSION`) unless asked not to or too small to gain."""
    data = np.asarray(data)
    if compress and data.size >= H5_COMPRESS_MIN:
        group.create_dataset(name, data=data, **H5_COMPRESSION)
    else:
        group.create_dataset(name, data=data)


def _write_h5(path, res, sensors: dict, an=None, states: dict | None = None, geometry: dict | None = None) -> None:
    """results.h5 (README "What `turnout run` writes"): ``signals/``, ``sensors/``, ``bodies/`` and
    ``analysis/`` (from ``an``), ``contact_geometry/`` (profile contact: per time, wheel and surface
    ``eta``, ``radius``, ``a``, ``b`` [m], ``p0`` [Pa]) and ``track/`` (the reduced states) only when
    ``states`` are given."""
    import h5py

    with h5py.File(path, "w") as f:
        f.attrs["description"] = "co-simulation signals (SI units, z up +) and track post-processing"
        g = f.create_group("signals")
        for k in ("t", "x", "z", "vz", "Fz", "parts", "rail_z"):
            _put(g, k, getattr(res, k))
        g = f.create_group("sensors")
        for k, v in sensors.items():
            _put(g, k, v)
        meta = getattr(an, "meta", None)
        if meta is not None:
            sl = meta["sleeper"]
            g = f.create_group(f"bodies/{meta['crossing_rail']}")
            _put(g, "coord", an.arrays["rail_x"])
            _put(g, "moment", meta["rail_hist"])
            g = f.create_group(f"bodies/sleeper_{meta['transition_sleeper']}")
            for k, v in (("coord", sl.coord), ("moment", sl.moment), ("w", sl.w), ("ballast_y", meta["y_p"]),
                         ("ballast_pressure", meta["p_t"])):
                _put(g, k, v)
        if an is not None and an.arrays:
            g = f.create_group("analysis")
            for k, v in an.arrays.items():
                _put(g, k, v)
        if geometry is not None:
            g = f.create_group("contact_geometry")
            g.attrs["description"] = ("profile contact per time, wheel and surface (rail or wing rail, nose): "
                                      "eta lateral contact position on the rail [m], radius rolling radius [m], "
                                      "a, b Hertz semi-axes along / across [m], p0 peak pressure [Pa]; NaN unloaded")
            for k, v in geometry.items():
                _put(g, k, v)
        if states is not None:
            g = f.create_group("track")
            g.attrs["description"] = ("reduced (Craig-Bampton) coordinates q of the track model built from the "
                                      "scenario, their rates v and accelerations a at the times t; "
                                      "displacements are u = T q")
            for k, v in states.items():
                _put(g, k, v, compress=False)  # see H5_COMPRESSION


def _write_frf(out_dir: Path, f: np.ndarray, H: np.ndarray, label: str) -> None:
    np.savetxt(out_dir / "frf.csv", np.column_stack([f, np.abs(H), np.degrees(np.angle(H)), H.real, H.imag]),
               delimiter=",", header="frequency,magnitude,phase_deg,real,imag", comments="", fmt="%.9g")
    plots.save(plots.plot_frf(f, {label: H}, f"receptance at {label}"), out_dir / "frf.png")


def frf_job(scenario, out_dir: Path, at: str | None, fmax: float) -> dict:
    """Receptance at ``at`` ("body:x", default the crossing rail at the transition) up to ``fmax`` [Hz]."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    model = track_model(scenario.track)
    side, x_ref, _ = reference_point(model)
    if at is None:
        body, x = model.layout.running_body(side, x_ref), x_ref
    else:
        body, _, xs = at.rpartition(":")
        x = float(xs)
        names = [b.name for b in model.bodies]
        if body not in names:
            import difflib
            hint = difflib.get_close_matches(body, names, n=1)
            raise UserInputError(f"--at: no body {body!r}" + (f" (did you mean {hint[0]!r}?)" if hint else "")
                                 + f"; bodies: {', '.join(n for n in names if not n.startswith('sleeper_'))}, "
                                   f"sleeper_0..sleeper_{len(model.layout.sleepers) - 1}")
        b = model.body(body)
        lo, hi = b.coords()[0], b.coords()[-1]
        if not lo <= x <= hi:
            raise UserInputError(f"--at: {x} m is outside {body} ({lo:.3f}..{hi:.3f} m)")
    if fmax > model.params.reduction.f_cut:
        import warnings
        warnings.warn(f"--fmax {fmax} Hz is above the model cut-off {model.params.reduction.f_cut} Hz; "
                      "raise track.reduction.f_cut for accuracy there")
    st = static_equilibrium(model, [])
    f = np.linspace(FRF_FMIN, fmax, FRF_POINTS)
    H = receptance(model, model.point(body, x), f, st.q)
    _write_frf(out_dir, f, H, f"{body}:{x:.3f}")
    return {"point": f"{body}:{x}", "fmax": fmax, "peak_frequency": float(f[np.argmax(np.abs(H))]),
            "static_receptance": float(abs(H[0]))}
