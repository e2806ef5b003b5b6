"""Jobs behind the command line: each takes a loaded Scenario and an output folder.

``run_scenario`` runs the co-simulation (:mod:`orchestrator.cosim.master`) and
post-processes the recorded track states with the same track model: contact
forces, wheel and rail displacements, bending-moment envelopes along the crossing
rail and the transition sleeper, the instants of maximum moment, ballast pressure.
"""
from __future__ import annotations

import json
import platform
import time
from pathlib import Path

import numpy as np

from track.frf import receptance
from orchestrator.inputs.track_model import track_model
from track.post import body_response
from track.statics import static_equilibrium
from track.timegrid import step_count

from orchestrator.results import plots
from orchestrator.results.analysis import analyse
from track.model import reference_point
from orchestrator.inputs.errors import UserInputError
from orchestrator.results.plots_layout import plot_layout

FRF_POINTS = 400          # frequencies of a receptance curve
FRF_FMIN = 5.0            # Hz


def _progress_bar(enabled: bool, total: int, desc: str):
    if not enabled:
        return None, lambda: None
    from tqdm import tqdm
    bar = tqdm(total=total, desc=desc, unit="step", mininterval=0.5)
    state = {"k": 0}

    def update(k: int, n: int) -> None:
        bar.update(k - state["k"])
        state["k"] = k

    return update, bar.close


def run_scenario(scenario, out_dir: Path, progress: bool = True, backend: str = "fmu") -> dict:
    """Co-simulation of ``scenario``; writes sensors.csv, results.h5, summary.json and plots.

    Returns the summary dict (also written as summary.json). If the run stops early
    (divergence, a failing FMU) everything computed so far is written first and a
    :class:`UserInputError` names the cause.
    """
    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    res = _cosimulate(scenario, out_dir, progress, backend)
    model = track_model(scenario.track)  # the same model (cached bodies) for post-processing
    summary = _run_summary(scenario, backend, model, res)
    # ---- signals first: nothing computed is lost if a later step fails
    _write_signals(out_dir, res, _virtual_sensors(scenario, model, res))
    Q0 = 0.5 * scenario.vehicle.axle_load
    summary["contact"] = _contact_summary(res, Q0)
    an = analyse(model, Q0, res)
    summary.update(an.scalars)
    meta = getattr(an, "meta", None)
    if meta is not None:
        summary.update({"crossing_rail": meta["crossing_rail"], "transition_sleeper": meta["transition_sleeper"],
                        "crossing_side": meta["crossing_side"]})
        _write_track_results(out_dir, scenario, model, res, an)
    else:
        _write_h5(out_dir / "results.h5", res)
    _plot_signals(out_dir, scenario, model.layout, res)
    summary["wall_seconds"]["job_total"] = time.perf_counter() - t_start
    summary["machine"] = f"{platform.machine()} {platform.system()} py{platform.python_version()}"
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2))
    if res.error:
        raise UserInputError(f"{res.error} (results up to t = {res.t[-1]:.4g} s written to {out_dir})")
    return summary


def _cosimulate(scenario, out_dir: Path, progress: bool, backend: str):
    """Run the co-simulation (FMU work files in ``out_dir/work``), with a progress bar; returns its result."""
    from orchestrator.cosim.master import run_cosim

    sim = scenario.simulation
    nsteps = step_count(sim.duration, sim.step)
    update, close = _progress_bar(progress, nsteps, "co-simulation")
    try:
        return run_cosim(scenario, backend=backend, work_dir=out_dir / "work", progress=update)
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


def _contact_summary(res, Q0: float) -> dict:
    """wheel<i> -> max and min contact force and ΔQ = max - ``Q0`` [N] (``Q0`` the static wheel load)."""
    return {f"wheel{i + 1}": {"max_Fz": float(np.nanmax(res.Fz[:, i])),
                              "min_Fz": float(np.nanmin(res.Fz[:, i])),
                              "delta_Q": float(np.nanmax(res.Fz[:, i]) - Q0)} for i in range(res.Fz.shape[1])}


def _write_track_results(out_dir: Path, scenario, model, res, an) -> None:
    """results.h5 with the crossing rail and transition sleeper, envelopes.png and moments.png (``an.meta``)."""
    meta = an.meta
    rail_name, sl_name = meta["crossing_rail"], f"sleeper_{meta['transition_sleeper']}"
    sl, rec = meta["sleeper"], res.track_record
    j_r, j_s = meta["j_rail"], meta["j_sleeper"]
    _write_h5(out_dir / "results.h5", res, rail_name, an.arrays["rail_x"], meta["rail_hist"], sl_name,
              sl, meta["y_p"], meta["p_t"])
    plots.save(plots.plot_envelopes(an.arrays["rail_x"], np.stack([an.arrays["rail_M_min"],
                                                                   an.arrays["rail_M_max"]]),
                                    sl.coord, np.stack([an.arrays["sleeper_M_min"], an.arrays["sleeper_M_max"]]),
                                    meta["y_p"], an.arrays["ballast_p_max"], rail_name, sl_name),
               out_dir / "envelopes.png")
    inst_r = {f"t = {rec['t'][j_r]:.4f} s (max rail moment)":
              body_response(model, rail_name, rec["q"][j_r], meta["loads_t"][j_r])}
    inst_s = {f"t = {rec['t'][j_s]:.4f} s (max sleeper moment)": body_response(model, sl_name, rec["q"][j_s])}
    plots.save(plots.plot_body_lines(inst_r, inst_s, f"{scenario.name}: instants of maximum moment",
                                     rail_name, f"{sl_name} (crossing transition)",
                                     marks_rail=[an.arrays["x_transition"][0]],
                                     marks_sleeper=list(an.arrays["wheel_y"])), out_dir / "moments.png")


def _plot_signals(out_dir: Path, scenario, lay, res) -> None:
    """layout.png, contact_forces.png and displacements.png (wheels and the rail under them)."""
    wheels = range(res.Fz.shape[1])
    plots.save(plot_layout(lay), out_dir / "layout.png")
    plots.save(plots.plot_time_series(res.t, {f"wheel {i + 1}": 1e-3 * res.Fz[:, i] for i in wheels},
                                      "contact force [kN]", f"{scenario.name}: wheel-rail contact forces"),
               out_dir / "contact_forces.png")
    series = {f"wheel {i + 1}": 1e3 * res.z[:, i] for i in wheels}
    series.update({f"rail under wheel {i + 1}": 1e3 * res.rail_z[:, i] for i in wheels})
    plots.save(plots.plot_time_series(res.t, series, "vertical displacement [mm]",
                                      f"{scenario.name}: wheel and rail displacement"), out_dir / "displacements.png")


def _virtual_sensors(scenario, model, res) -> dict:
    """The sensor layout's signals (DESIGN.md §4.3) at the output times; {} without a track record."""
    from track.sensors import compile_sensors, sensor_signals

    from orchestrator.inputs.sensor_layout import layout_of, scenario_sensors

    rec = res.track_record
    if rec is None or "a" not in rec or len(rec["t"]) < 2 or len(rec["t"]) != len(res.t):
        return {}
    sensors = scenario_sensors(scenario, model)
    if not sensors:
        return {}
    layout = layout_of(scenario)
    compiled = compile_sensors(model, sensors)
    dt = float(np.median(np.diff(rec["t"])))
    return sensor_signals(model, compiled, rec["q"], rec["v"], rec["a"], dt, layout.displacement_highpass)


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


def _write_h5(path, res, rail_name=None, rail_coord=None, rail_hist=None, sl_name=None, sl_resp=None,
              y_p=None, p_t=None) -> None:
    import h5py
    with h5py.File(path, "w") as f:
        f.attrs["description"] = "co-simulation signals (SI units, z up +) and track post-processing"
        for k in ("t", "x", "z", "vz", "Fz", "parts", "rail_z"):
            f[f"signals/{k}"] = getattr(res, k)
        if res.track_record is not None:
            for k, v in res.track_record.items():
                f[f"track/{k}"] = v
        if rail_name is not None:
            g = f.create_group(f"bodies/{rail_name}")
            g["coord"], g["moment"] = rail_coord, rail_hist
            g = f.create_group(f"bodies/{sl_name}")
            g["coord"], g["moment"], g["w"] = sl_resp.coord, sl_resp.moment, sl_resp.w
            g["ballast_y"], g["ballast_pressure"] = y_p, p_t


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
