"""The source papers' figures in one command (`turnout figures`).

Seed 001 (Pålsson 2020), 60E1-R760-1:15 crossing, quarter vehicle, through route:
a sweep over speed (10-200 km/h) x impact angle (6/12/18 mrad) x rail-pad stiffness
(120 / 1200 MN/m) with :func:`orchestrator.sweeps.sweep.run_sweep` (its executors and
resumable store), then
- fig3_dQ.png: ΔQ against speed x impact angle, soft and stiff pads (seed Fig. 3);
- fig4_rail.png: crossing-rail deflection and moment at the instant of maximum rail
  moment, 200 km/h for the three angles and 10 km/h as quasi-static reference (Fig. 4);
- fig5_sleeper.png: the same for the sleeper under the crossing transition, with the
  wheels' lateral positions dashed (Fig. 5);
- fig6_pressure.png: sleeper deflection and sleeper-ballast pressure along that
  sleeper at the instant of maximum sleeper moment (Fig. 6);
- fig7_pads.png: sleeper moment with the soft and the stiff pad (Fig. 7);
- seed001_table.csv: one row per run.

Seed 000 (Vilhelmson et al.), 1:12 crossing panel (the default scenario):
- seed000_table1.csv: dofs and CPU time of the beam and the 3D solid crossing rail
  models (seed Table 1), the solid's one-time mesh + reduction cost apart;
- fig6_receptance.png, seed000_receptance.csv: direct receptance at the crossing nose
  (the transition point), beam vs 3D solid crossing rail, 5 Hz - 2 kHz (seed Fig. 6),
  with the models' cut-off raised to 2.5 kHz.
- fig_seed000_pressure.png, seed000_pressure.csv: ballast pressure along the crossing
  transition sleeper (sensor group A), "measured" vs nominal vs calibrated model. There is
  no field record in this repository: the "measurement" is synthetic — the measurement
  scenario (one wheelset, 120 km/h) with a void under the transition sleeper like the one
  seed 000 found, 1 % noise — and the calibrated model is what `turnout diagnose` fits
  to it (seed000_pressure/: diagnosis.json, report.md, extended.yaml).

Profile study (issue 15, the seed's proposed next step; scenarios/profiles.yaml, the 1:12
crossing with `track.crossing.geometry: profiles`): hollow depth (0, 2 mm) x lateral offset
(-3, 0, +3 mm) x speed (80, 120 km/h), 12 runs:
- profiles_study.png: ΔQ, the emergent impact angle and the transfer point behind the
  theoretical crossing point against speed, one line per hollow depth x offset;
- profiles_table.csv: one row per run.
"""
from __future__ import annotations

import csv
import time
from pathlib import Path

import numpy as np

from orchestrator.results.plots import _plt, save  # the package's plotting setup (Agg backend) and writer

SEED001 = "seed001/crossing_1_15_quarter.yaml"   # in the repository's scenarios/ folder
SEED000 = "crossing_1_12_through_120.yaml"
FRF_FMAX = 2000.0      # Hz, seed 000 Fig. 6
FRF_F_CUT = 2500.0     # Hz: model cut-off for that figure (reduced frequencies within 1 % below it)
SPEEDS_KMH = (10, 40, 80, 120, 160, 200)   # seed 001 Fig. 3 range
ANGLES = (0.006, 0.012, 0.018)             # rad: nominal, worn, severely worn
PADS = (1.2e8, 1.2e9)                      # N/m: indirect (soft) and direct (stiff) fixing
KMH = 1 / 3.6
PROFILES = "profiles.yaml"                 # in scenarios/
PROFILE_STUDY = {"vehicle.wheel_profile.hollow_depth": [0.0, 0.002],     # m: new, hollow-worn
                 "vehicle.lateral_offset": [-0.003, 0.0, 0.003],         # m, towards the crossing wheel's field side
                 "vehicle.speed": [22.2, 33.3]}                          # m/s: 80, 120 km/h


def seed001_variations(speeds_kmh=SPEEDS_KMH, angles=ANGLES, pads=PADS) -> dict[str, list]:
    """The grid of the seed 001 study (keys are scenario key paths)."""
    return {"vehicle.speed": [round(v * KMH, 4) for v in speeds_kmh],
            "track.crossing.impact_angle": list(angles),
            "track.rail_pad.stiffness": list(pads)}


def _arrays(run_dir: Path) -> dict:
    """The arrays a run wrote (``run_dir/arrays.npz``, :func:`orchestrator.sweeps.study.run_case`)."""
    with np.load(Path(run_dir) / "arrays.npz") as d:
        return {k: d[k] for k in d.files}


def _pick(rows, speed, angle, pad):
    """The row of ``speed`` [m/s], impact ``angle`` [rad] and rail-pad stiffness ``pad`` [N/m], or ``None``."""
    for r in rows:
        if (abs(r["vehicle.speed"] - speed) < 1e-6 and abs(r["track.crossing.impact_angle"] - angle) < 1e-12
                and abs(r["track.rail_pad.stiffness"] - pad) < 1.0):
            return r
    return None


def seed001_figures(rows: list[dict], run_dir_of, out_dir: Path) -> list[Path]:
    """Figures 3-7 of seed 001 from the sweep rows (``run_dir_of(row) -> Path``)."""
    plt = _plt()
    out_dir = Path(out_dir)
    files = [_fig3_delta_q(plt, rows, out_dir)]
    # Figs. 4-6: 200 km/h for the three angles + 10 km/h reference, soft pad
    speeds = sorted({round(r["vehicle.speed"] / KMH) for r in rows})
    cases = [(speeds[-1], a) for a in ANGLES] + [(speeds[0], ANGLES[0])]
    data = []
    for kmh, ang in cases:
        r = _pick(rows, round(kmh * KMH, 4), ang, PADS[0])
        if r is not None:
            data.append((f"{kmh} km/h, {1e3 * ang:.0f} mrad", _arrays(run_dir_of(r))))
    files += _fig45_body_lines(plt, data, out_dir)
    files.append(_fig6_pressure(plt, data, out_dir))
    files.append(_fig7_pads(plt, rows, run_dir_of, speeds, out_dir))
    return files


def _fig3_delta_q(plt, rows: list[dict], out_dir: Path) -> Path:
    """Fig. 3: ΔQ against speed x impact angle, one panel per rail pad; returns ``fig3_dQ.png``."""
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    for ax, pad in zip(axes, PADS):
        for ang, mk in zip(ANGLES, "o^s"):
            sel = sorted((r for r in rows if abs(r["track.rail_pad.stiffness"] - pad) < 1 and
                          abs(r["track.crossing.impact_angle"] - ang) < 1e-12), key=lambda r: r["vehicle.speed"])
            vb = [r["vehicle.speed"] * ang for r in sel]
            ax.plot(vb, [1e-3 * r["delta_Q"] for r in sel], mk + "-", label=f"{1e3 * ang:.0f} mrad")
        ax.set_title(f"rail pad {pad / 1e6:.0f} MN/m")
        ax.set_xlabel("speed x impact angle [m/s]")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("ΔQ = Q_max - Q0 [kN]")
    axes[0].legend()
    fig.tight_layout()
    path = out_dir / "fig3_dQ.png"
    save(fig, path)
    return path


def _fig45_body_lines(plt, data: list[tuple[str, dict]], out_dir: Path) -> list[Path]:
    """Figs. 4-5: deflection and moment of the crossing rail and the transition sleeper.

    ``data`` is ``[(label, arrays of the run)]``; returns ``fig4_rail.png``, ``fig5_sleeper.png``.
    """
    files = []
    for name, xkey, wkey, mkey, title, xlabel in (
            ("fig4_rail.png", "rail_x", "rail_w_at_max", "rail_M_at_max",
             "crossing rail at the instant of maximum rail moment", "x [m]"),
            ("fig5_sleeper.png", "sleeper_y", "sleeper_w_at_max", "sleeper_M_at_max",
             "sleeper under the crossing transition at the instant of maximum sleeper moment", "y [m]")):
        fig, ax = plt.subplots(2, 1, figsize=(8, 6.5), sharex=True)
        for lab, a in data:
            ax[0].plot(a[xkey], 1e3 * a[wkey], label=lab)
            ax[1].plot(a[xkey], 1e-3 * a[mkey], label=lab)
        if data and xkey == "sleeper_y":
            for y in data[0][1]["wheel_y"]:
                for a_ in ax:
                    a_.axvline(y, ls="--", c="0.5", lw=0.8)
        if data and xkey == "rail_x":
            for a_ in ax:
                a_.axvline(data[0][1]["x_transition"][0], ls=":", c="0.5", lw=0.8)
        files.append(_save_two_panels(fig, ax, "bending moment [kN m]", xlabel, title, out_dir / name))
    return files


def _fig6_pressure(plt, data: list[tuple[str, dict]], out_dir: Path) -> Path:
    """Fig. 6: sleeper deflection and sleeper-ballast pressure (``data`` as in Figs. 4-5); returns its path."""
    fig, ax = plt.subplots(2, 1, figsize=(8, 6.5), sharex=True)
    for lab, a in data:
        ax[0].plot(a["sleeper_y"], 1e3 * a["sleeper_w_at_max"], label=lab)
        ax[1].plot(a["ballast_y"], 1e-3 * a["ballast_p_at_max_sleeper"], "o-", label=lab)
    return _save_two_panels(fig, ax, "sleeper-ballast pressure [kPa]", "y [m]",
                            "sleeper under the crossing transition at the instant of maximum sleeper moment",
                            out_dir / "fig6_pressure.png")


def _save_two_panels(fig, ax, lower_ylabel: str, xlabel: str, title: str, path: Path) -> Path:
    """Label a (displacement over ``lower_ylabel``) pair of axes ``ax``, write ``fig`` to ``path``; returns it."""
    ax[0].set_ylabel("vertical displacement [mm]")
    ax[1].set_ylabel(lower_ylabel)
    ax[1].set_xlabel(xlabel)
    ax[0].set_title(title)
    ax[0].legend(fontsize=8)
    for a_ in ax:
        a_.grid(alpha=0.3)
    fig.tight_layout()
    save(fig, path)
    return path


def _fig7_pads(plt, rows: list[dict], run_dir_of, speeds: list[int], out_dir: Path) -> Path:
    """Fig. 7: sleeper moment, soft vs stiff pad, worn crossing, highest and lowest speed; returns its path."""
    fig, ax = plt.subplots(figsize=(8, 4))
    for kmh in (speeds[-1], speeds[0]):
        for pad, ls in zip(PADS, ("-", "--")):
            r = _pick(rows, round(kmh * KMH, 4), ANGLES[1], pad)
            if r is not None:
                a = _arrays(run_dir_of(r))
                ax.plot(a["sleeper_y"], 1e-3 * a["sleeper_M_at_max"], ls,
                        label=f"{kmh} km/h, pad {pad / 1e6:.0f} MN/m")
    ax.set_xlabel("y [m]")
    ax.set_ylabel("sleeper bending moment [kN m]")
    ax.set_title("sleeper moment at its maximum, 12 mrad: soft vs stiff rail pad")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    path = out_dir / "fig7_pads.png"
    save(fig, path)
    return path


def seed000_table(out_dir: Path) -> list[Path]:
    """Seed 000 Table 1: dofs and CPU time of the default scenario, beam and 3D solid crossing rail.

    The reduced bodies are built before the clock starts (the seed, too, leaves the
    substructure generation out); the solid's one-time mesh + reduction cost is a
    column of its own (0 when it came from the cache).
    """
    from dataclasses import replace

    from orchestrator.cosim.master import run_cosim
    from orchestrator.inputs.scenario import bundled_scenario, load_scenario
    from orchestrator.inputs.track_model import track_model

    sc = load_scenario(bundled_scenario(SEED000))
    rows = []
    for label, model_name, seed_dofs, seed_cpu in (("beam", "beam", 798, 30),
                                                   ("3D solid crossing rail", "solid", 904, 40)):
        s = replace(sc, track=replace(sc.track, model=model_name))
        model = track_model(s.track)
        one_time = model.stats.t_solid_mesh + model.stats.t_solid_reduction
        t0 = time.process_time()
        res = run_cosim(s, backend="inprocess", record_states=False)
        cpu = time.process_time() - t0
        rows.append([label, model.n, model.stats.fom_dofs, f"{one_time:.1f}", f"{res.t[-1]:.3f}", f"{cpu:.1f}",
                     seed_dofs, seed_cpu])
    path = Path(out_dir) / "seed000_table1.csv"
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["model", "reduced dofs", "full dofs", "solid mesh + reduction [s]", "simulated [s]",
                    "run CPU [s]", "seed 000 dofs", "seed 000 CPU [min]"])
        w.writerows(rows)
    note = Path(out_dir) / "seed000_README.txt"
    note.write_text(
        "Seed 000 figures: Table 1 (seed000_table1.csv); Fig. 6, the receptance at the crossing nose, beam vs\n"
        "3D solid crossing rail (fig6_receptance.png, seed000_receptance.csv); the ballast pressure along the\n"
        "transition sleeper, measured vs nominal vs calibrated (fig_seed000_pressure.png, seed000_pressure.csv)\n"
        "- the 'measurement' is synthetic (a void under the transition sleeper, 1 % noise), the calibrated\n"
        "model is what `turnout diagnose` fits (seed000_pressure/report.md).\n")
    return [path, note] + seed000_receptance(out_dir)


def seed000_receptance(out_dir: Path, fmax: float = FRF_FMAX, n_freqs: int = 400) -> list[Path]:
    """Seed 000 Fig. 6: direct receptance at the crossing nose, beam vs 3D solid crossing rail.

    Both models of the default scenario with the cut-off raised to ``FRF_F_CUT``,
    linearized about their static equilibrium under self-weight; unit force at the
    transition point on the crossing side.
    """
    from dataclasses import replace

    from orchestrator.inputs.scenario import bundled_scenario, load_scenario
    from orchestrator.inputs.track_model import track_model
    from orchestrator.results.plots import plot_frf, save
    from track.frf import receptance
    from track.statics import static_equilibrium

    sc = load_scenario(bundled_scenario(SEED000))
    f = np.geomspace(5.0, fmax, n_freqs)
    H = {}
    for label, model_name in (("beam", "beam"), ("3D solid crossing rail", "solid")):
        tp = replace(sc.track, model=model_name, reduction=replace(sc.track.reduction, f_cut=FRF_F_CUT))
        model = track_model(tp)
        lay = model.layout
        H[label] = receptance(model, model.rail_point(lay.crossing_side, lay.x_transition), f,
                              static_equilibrium(model, []).q)
    out_dir = Path(out_dir)
    csv_path = out_dir / "seed000_receptance.csv"
    hb, hs = H["beam"], H["3D solid crossing rail"]
    np.savetxt(csv_path, np.column_stack([f, np.abs(hb), np.abs(hs), np.abs(hs) / np.abs(hb) - 1]),
               delimiter=",", header="frequency,beam,solid,solid/beam-1", comments="", fmt="%.9g")
    fig = plot_frf(f, H, "receptance at the crossing nose (seed 000 Fig. 6)")
    for ax in fig.axes:
        ax.set_xscale("log")
        ax.axvline(250.0, color="0.5", lw=0.8, ls="--")
    png = out_dir / "fig6_receptance.png"
    save(fig, png)
    return [csv_path, png]


SEED000_MEASURED = "measurement/crossing_quarter_120.yaml"
SEED000_VOID = (0.0, 0.4e-3, 0.9e-3, 0.9e-3, 0.4e-3, 0.0)   # m: DESIGN.md §4.2's example void profile


def seed000_pressure(out_dir: Path, workers: int | None = None, scheduler: str | None = None,
                     progress: bool = True) -> list[Path]:
    """Seed 000's measured vs nominal vs calibrated ballast pressure (module docstring)."""
    from orchestrator.inputs.scenario import bundled_scenario, load_scenario
    from orchestrator.inputs.sensor_layout import layout_of, resolve
    from orchestrator.inputs.track_model import track_model
    from orchestrator.inverse.diagnose import diagnose
    from orchestrator.inverse.objective import Target
    from orchestrator.inverse.synthetic import Effect, synthesize
    from track.model import reference_point

    out_dir = Path(out_dir)
    path = bundled_scenario(SEED000_MEASURED)
    sc = load_scenario(path)
    model = track_model(sc.track)
    k_t = reference_point(model)[2]
    work = out_dir / "seed000_pressure"
    work.mkdir(parents=True, exist_ok=True)
    measured = work / "field_passage_synthetic.csv"
    synthesize(sc, Effect("ballast_void", k_t, {"gaps": list(SEED000_VOID)}), measured, seed=0)
    result = diagnose(path, measured, work, workers=workers, scheduler=scheduler, progress=progress)
    layout = layout_of(sc)
    cells = [s for s in resolve(layout, model) if s.group == "A"]
    target = Target.read(measured, layout)
    lines = _simulated_channels(target, layout, {"nominal": sc,
                                                 "calibrated": load_scenario(work / result.extended_scenario)})
    peak = {"measured": [np.nanmax(target.measured.channels[c.id]) for c in cells]}
    peak.update({k: [np.nanmax(v[c.id]) for c in cells] for k, v in lines.items()})
    csv_path = _write_pressure_table(out_dir / "seed000_pressure.csv", cells, peak)
    png = _plot_pressure(cells, peak, target, lines, k_t, result.named_cause.to_json(),
                         out_dir / "fig_seed000_pressure.png")
    return [csv_path, png, work / "report.md"]


def _simulated_channels(target, layout, scenarios: dict) -> dict[str, dict]:
    """label -> the simulated channels of ``scenarios[label]``, aligned to ``target`` (an objective Target).

    The first run fixes ``target``'s time shift when it has none yet.
    """
    from orchestrator.cosim.sensing import simulate_sensors

    lines = {}
    for label, scen in scenarios.items():
        run = simulate_sensors(scen, layout, reconstruct=False)
        if target.shift is None:
            target.align_to(run.t, run.signals)
        lines[label] = target.compare(run.t, run.signals).simulated
    return lines


def _write_pressure_table(path: Path, cells: list, peak: dict[str, list]) -> Path:
    """``seed000_pressure.csv``: each group-A cell's position and peak pressure, measured/nominal/calibrated."""
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["sensor", "y [m]", "measured peak [Pa]", "nominal peak [Pa]", "calibrated peak [Pa]"])
        for i, c in enumerate(cells):
            w.writerow([c.id, f"{c.coord:.3f}"] + [f"{peak[k][i]:.1f}" for k in ("measured", "nominal", "calibrated")])
    return path


def _plot_pressure(cells: list, peak: dict[str, list], target, lines: dict[str, dict], k_t: int, named: dict,
                   path: Path) -> Path:
    """Peak pressure per cell, and the time history of the cell the nominal model misses most; returns ``path``."""
    plt = _plt()
    fig, ax = plt.subplots(1, 2, figsize=(12, 4.2))
    y = np.array([c.coord for c in cells])
    for label, style in (("measured", dict(c="0.3", marker="o", ls="")), ("nominal", dict(c="C0", marker="s")),
                         ("calibrated", dict(c="C3", marker="^", ls="--"))):
        ax[0].plot(y, 1e-3 * np.array(peak[label]), label=label, **style)
    ax[0].set_xlabel("lateral position on the transition sleeper y [m]")
    ax[0].set_ylabel("peak ballast pressure [kPa]")
    ax[0].set_title(f"sleeper {k_t}: peak pressure per cell")
    worst = max(cells, key=lambda c: abs(peak["nominal"][cells.index(c)] - peak["measured"][cells.index(c)]))
    t = target.measured.t
    ax[1].plot(t, 1e-3 * target.measured.channels[worst.id], c="0.3", lw=0.8, label="measured")
    for label, c in (("nominal", "C0"), ("calibrated", "C3")):
        ax[1].plot(t, 1e-3 * lines[label][worst.id], c=c, lw=1.0, label=label)
    ax[1].set_xlabel("time [s]")
    ax[1].set_ylabel(f"{worst.id} pressure [kPa]")
    ax[1].set_title(f"calibrated: {named['cause']}" + (f" at sleeper {named['sleeper']}" if "sleeper" in named else ""))
    for a in ax:
        a.grid(alpha=0.3)
        a.legend(fontsize=8)
    fig.suptitle("seed 000: measured (synthetic) vs nominal vs calibrated ballast pressure")
    fig.tight_layout()
    save(fig, path)
    return path


def make_figures(out_dir: Path, study: str = "all", workers: int | None = None, scheduler: str | None = None,
                 progress: bool = True, speeds_kmh=None) -> list[Path]:
    """Run the studies (resumable) and write the figures into ``out_dir``.

    ``speeds_kmh`` defaults to :data:`SPEEDS_KMH` (the seed's range).
    """
    speeds_kmh = SPEEDS_KMH if speeds_kmh is None else tuple(speeds_kmh)
    from orchestrator.sweeps.sweep import run_sweep

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    files: list[Path] = []
    if study in ("seed001", "all"):
        from orchestrator.inputs.scenario import bundled_scenario
        from orchestrator.sweeps.plan import expand_grid
        res = run_sweep(bundled_scenario(SEED001), expand_grid(seed001_variations(speeds_kmh)),
                        out_dir / "seed001_runs", workers=workers, scheduler=scheduler, progress=progress)
        if res.failed:
            raise RuntimeError(f"seed 001 study: {res.summary()}")
        files += seed001_figures(res.rows, lambda r: res.runs_dir / r["run_id"], out_dir)
        table = out_dir / "seed001_table.csv"
        table.write_bytes(res.table.read_bytes())
        files.append(table)
    if study in ("seed000", "all"):
        files += seed000_table(out_dir)
        files += seed000_pressure(out_dir, workers=workers, scheduler=scheduler, progress=progress)
    if study in ("profiles", "all"):
        files += profile_study(out_dir, workers=workers, scheduler=scheduler, progress=progress)
    return files


def profile_study(out_dir: Path, workers: int | None = None, scheduler: str | None = None,
                  progress: bool = True) -> list[Path]:
    """Run the profile study (:data:`PROFILE_STUDY` on :data:`PROFILES`, resumable) and write
    ``profiles_study.png`` and ``profiles_table.csv`` into ``out_dir``."""
    from orchestrator.inputs.scenario import bundled_scenario
    from orchestrator.sweeps.plan import expand_grid
    from orchestrator.sweeps.sweep import run_sweep
    out_dir = Path(out_dir)
    res = run_sweep(bundled_scenario(PROFILES), expand_grid(PROFILE_STUDY), out_dir / "profiles_runs",
                    workers=workers, scheduler=scheduler, progress=progress)
    if res.failed:
        raise RuntimeError(f"profile study: {res.summary()}")
    table = out_dir / "profiles_table.csv"
    table.write_bytes(res.table.read_bytes())
    return [profile_study_figure(res.rows, out_dir / "profiles_study.png"), table]


def profile_study_figure(rows: list[dict], path: Path) -> Path:
    """ΔQ, emergent impact angle and transfer point against speed, one line per hollow depth x
    lateral offset (colour: offset; solid, circles: new wheel; dashed, squares: hollow-worn), from the rows of a sweep
    over :data:`PROFILE_STUDY`'s keys (numbers, or their text as in ``sweep.csv``)."""
    plt = _plt()
    keys = list(PROFILE_STUDY)
    num = [{k: float(r[k]) for k in keys + ["delta_Q", "impact_angle_emergent", "transfer_behind_tcp"]}
           for r in rows]
    panels = (("delta_Q", 1e-3, "ΔQ [kN]"), ("impact_angle_emergent", 1e3, "emergent impact angle [mrad]"),
              ("transfer_behind_tcp", 1e3, "transfer behind the TCP [mm]"))
    fig, axes = plt.subplots(1, 3, figsize=(13, 4))
    hollows = sorted({r[keys[0]] for r in num})
    offsets = sorted({r[keys[1]] for r in num})
    for ax, (col, scale, label) in zip(axes, panels):
        for h, ls in zip(hollows, ("o-", "s--", "^:")):
            for off, colour in zip(offsets, ("C0", "C1", "C2", "C3", "C4")):
                sel = sorted((r for r in num if r[keys[0]] == h and r[keys[1]] == off), key=lambda r: r[keys[2]])
                ax.plot([3.6 * r[keys[2]] for r in sel], [scale * r[col] for r in sel], ls, color=colour,
                        label=f"hollow {1e3 * h:.0f} mm, offset {1e3 * off:+.0f} mm")
        ax.set_xlabel("speed [km/h]")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7, handlelength=3)
    fig.suptitle("1:12 crossing, S1002 on the profile contact: wheel wear x lateral offset x speed")
    fig.tight_layout()
    save(fig, path)
    return Path(path)
