"""Jobs behind the command line: each takes a loaded Scenario and an output folder.

``run_scenario`` is, until the vehicle co-simulation lands, a *track-only* run: the
vehicle's static wheel loads move at the scenario speed over the reduced track
(from static equilibrium), and the job writes the signals, the bending-moment
envelopes, the static deflection lines at the crossing transition and the
receptance there.
"""
from __future__ import annotations

import json
import platform
import time
from pathlib import Path

import numpy as np

from track.dynamics import simulate_moving_loads
from track.frf import receptance
from track.model import TrackModel, build_track
from track.post import body_response, sleeper_pressure
from track.statics import static_equilibrium
from track.wheels import static_wheel_loads, wheel_offsets

from . import plots
from .errors import UserInputError
from .plots_layout import plot_layout

FRF_POINTS = 400          # frequencies of a receptance curve
FRF_FMIN = 5.0            # Hz
MARGIN_SLEEPERS = 2       # wheels stay this many sleepers inside the panel ends


def _reference(model: TrackModel) -> tuple[str, float, int]:
    """(crossing-side wheel, x of the crossing transition, transition sleeper index)."""
    lay = model.layout
    if lay.x_transition is not None:
        k = lay.params.transition_sleeper
        k = len(lay.sleepers) // 2 + 1 if k is None else k
        return lay.crossing_side, lay.x_transition, k
    k = len(lay.sleepers) // 2
    return "left", lay.sleepers[k].x, k


def _check_vehicle(scenario) -> str:
    kind = scenario.vehicle.fmu
    if kind not in ("bogie", "quarter"):
        raise UserInputError(f"vehicle.fmu: {kind!r}: third-party vehicle FMUs need the co-simulation, "
                             "which this version does not have yet; use 'bogie' or 'quarter'")
    return kind


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


def run_scenario(scenario, out_dir: Path, progress: bool = True) -> dict:
    """Track-only run of ``scenario``; writes sensors.csv, results.h5, summary.json, plots.

    Returns the summary dict (also written as summary.json).
    """
    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    kind = _check_vehicle(scenario)
    veh, sim = scenario.vehicle, scenario.simulation
    model = build_track(scenario.track)
    lay = model.layout
    side, x_ref, k_tr = _reference(model)
    spacing = lay.params.sleeper_spacing
    offsets = wheel_offsets(kind)
    x_first, x_last = lay.sleepers[0].x, lay.sleepers[-1].x
    x_front = sim.x_start if sim.x_start is not None else x_first - min(offsets) + MARGIN_SLEEPERS * spacing
    x_end = x_last - MARGIN_SLEEPERS * spacing
    duration = min(sim.duration, (x_end - x_front) / veh.speed)
    if duration <= 0:
        raise UserInputError(f"simulation.x_start: {x_front:.3f} m leaves no room in the panel "
                             f"(wheels must stay within {x_first:.2f}..{x_end:.2f} m)")
    h = sim.step
    every = max(1, int(round(sim.output_step / h)))
    loads = static_wheel_loads(kind, veh.axle_load, x_front)

    # static deflection lines with the front wheelset over the crossing transition
    static_loads = [(model.rail_point(ld.side, x_ref + (ld.x0 - x_front)), ld.force) for ld in loads]
    st = static_equilibrium(model, static_loads)
    rail_name = lay.running_body(side, x_ref)
    sl_name = f"sleeper_{k_tr}"

    nsteps = int(round(duration / h))
    update, close = _progress_bar(progress, nsteps, "track run")
    try:
        res = simulate_moving_loads(model, loads, veh.speed, duration, h, every, progress=update)
    finally:
        close()

    # ---- post-processing
    Fw = np.array([ld.force for ld in loads])
    wheel_points = [[(model.rail_point(ld.side, x), ld.force) for ld, x in zip(loads, xs)] for xs in res.x]
    rail_hist = np.array([body_response(model, rail_name, q, pts).moment for q, pts in zip(res.q, wheel_points)])
    rail_coord = model.body(rail_name).coords()
    sl_resp = body_response(model, sl_name, res.q)
    y_p, p_t = sleeper_pressure(model, k_tr, res.q, res.v)
    seat_y = [y for sl, y in zip(model.pads.sleeper, model.pads.y) if sl == k_tr]
    w_seat = np.array([body_response(model, sl_name, res.q).w[:, np.argmin(np.abs(model.body(sl_name).coords() - y))]
                       for y in seat_y]).T

    # ---- files: signals first (nothing computed is lost if a later step fails)
    cols = {"time": res.t}
    for i in range(len(loads)):
        cols[f"wheel{i + 1}_rail_w"] = res.w[:, i]
    for j, y in enumerate(seat_y):
        cols[f"{sl_name}_w_seat{j + 1}"] = w_seat[:, j]
    for j in range(y_p.size):
        cols[f"{sl_name}_p{j + 1}"] = p_t[:, j]
    header = ",".join(cols)
    np.savetxt(out_dir / "sensors.csv", np.column_stack(list(cols.values())), delimiter=",",
               header=header, comments="", fmt="%.9g")
    _write_h5(out_dir / "results.h5", model, res, Fw, rail_name, rail_coord, rail_hist, sl_name, sl_resp)

    summary = {
        "scenario": scenario.name,
        "kind": "track-only (moving static wheel loads; vehicle co-simulation not yet available)",
        "vehicle": kind, "speed": veh.speed, "axle_load": veh.axle_load,
        "duration": float(res.t[-1]), "step": h, "x_front_start": x_front,
        "dofs": {"reduced": model.n, "full": model.stats.fom_dofs, "bodies": model.stats.bodies},
        "build_seconds": {"mesh_assembly": model.stats.t_mesh_assembly, "reduction": model.stats.t_reduction,
                          "global": model.stats.t_global},
        "static": {"residual": st.residual, "iterations": st.iterations,
                   "rail_w_at_transition": float(static_loads[0][0].value(st.q, static_loads[0][1]))},
        "counters": vars(res.counters),
        "crossing_rail": rail_name, "transition_sleeper": k_tr,
        "max_rail_moment": float(rail_hist.max()), "min_rail_moment": float(rail_hist.min()),
        "max_sleeper_moment": float(sl_resp.moment.max()), "min_sleeper_moment": float(sl_resp.moment.min()),
        "max_ballast_pressure_transition": float(p_t.max()),
        "wall_seconds": None, "machine": f"{platform.machine()} {platform.system()} py{platform.python_version()}",
        "error": res.error,
    }

    # ---- plots
    plots.save(plot_layout(lay), out_dir / "layout.png")
    static_rail = {"static, front wheelset at transition": body_response(model, rail_name, st.q, static_loads)}
    static_sl = {"static": body_response(model, sl_name, st.q)}
    wheel_y = sorted({y for y in seat_y})
    plots.save(plots.plot_body_lines(static_rail, static_sl, f"{scenario.name}: static equilibrium",
                                     f"{rail_name} (rail under the {side} wheels)", f"{sl_name} (transition)",
                                     marks_rail=[x_ref], marks_sleeper=wheel_y), out_dir / "static.png")
    env_r = np.stack([rail_hist.min(axis=0), rail_hist.max(axis=0)])
    env_s = np.stack([sl_resp.moment.min(axis=0), sl_resp.moment.max(axis=0)])
    plots.save(plots.plot_envelopes(rail_coord, env_r, sl_resp.coord, env_s, y_p, p_t.max(axis=0),
                                    rail_name, sl_name), out_dir / "envelopes.png")
    plots.save(plots.plot_time_series(res.t, {f"wheel {i + 1}": 1e3 * res.w[:, i] for i in range(len(loads))},
                                      "rail displacement under wheel [mm]", scenario.name),
               out_dir / "wheel_displacement.png")
    f = np.linspace(FRF_FMIN, scenario.track.reduction.f_cut, FRF_POINTS)
    H = receptance(model, model.point(rail_name, x_ref), f, res.q_static)
    _write_frf(out_dir, f, H, f"{rail_name}:{x_ref:.3f}")
    summary["wall_seconds"] = time.perf_counter() - t_start
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2))
    if res.error:
        raise UserInputError(f"{res.error} (results up to t = {res.t[-1]:.4g} s written to {out_dir})")
    return summary


def _write_h5(path, model, res, Fw, rail_name, rail_coord, rail_hist, sl_name, sl_resp) -> None:
    import h5py
    with h5py.File(path, "w") as f:
        f.attrs["description"] = "track-only run: generalized coordinates and derived quantities, SI units"
        f["t"] = res.t
        f["q"] = res.q
        f["q_static"] = res.q_static
        f["wheel_x"] = res.x
        f["wheel_rail_w"] = res.w
        f["wheel_force"] = Fw
        g = f.create_group(f"bodies/{rail_name}")
        g["coord"] = rail_coord
        g["moment"] = rail_hist
        g = f.create_group(f"bodies/{sl_name}")
        g["coord"] = sl_resp.coord
        g["moment"] = sl_resp.moment
        g["w"] = sl_resp.w


def _write_frf(out_dir: Path, f: np.ndarray, H: np.ndarray, label: str) -> None:
    np.savetxt(out_dir / "frf.csv", np.column_stack([f, np.abs(H), np.degrees(np.angle(H)), H.real, H.imag]),
               delimiter=",", header="frequency,magnitude,phase_deg,real,imag", comments="", fmt="%.9g")
    plots.save(plots.plot_frf(f, {label: H}, f"receptance at {label}"), out_dir / "frf.png")


def frf_job(scenario, out_dir: Path, at: str | None, fmax: float) -> dict:
    """Receptance at ``at`` ("body:x", default the crossing rail at the transition) up to ``fmax`` [Hz]."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    model = build_track(scenario.track)
    side, x_ref, _ = _reference(model)
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
