"""What a calibration reports: the content of ``calibration.json``, ``report.md`` and the plots.

Part of :mod:`orchestrator.inverse.calibrate`. :func:`summarise` turns the stages'
:class:`~orchestrator.inverse.calibration_stages.Outcome` into the JSON-able summary (the
file format of ``calibration.json``: :class:`orchestrator.inverse.calibrate.CalibrationResult`
reads and writes it), :func:`report` writes ``report.md`` from that summary, and
:func:`plots` draws ``calibration_cv.png``, ``calibration_sensitivity.png`` and
``calibration_signals.png``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from orchestrator.inverse.calibration_params import values_at
from orchestrator.inverse.calibration_runs import SIGNALS_FILE, channels_of
from orchestrator.inverse.surrogate import CV_FOLDS, KERNEL

__all__ = ["summarise", "report", "plots"]

SIGNAL_PLOT_IDS = ("A1", "A2", "A3", "A4", "A5", "A6")  # the ballast pressures of seed 000 Fig. 2, group A


# ======================================================================================
# calibration.json
# ======================================================================================
def summarise(setup, found) -> dict:
    """The content of ``calibration.json`` (``plots`` not yet, ``wall_time_s`` ``None``).

    Parameters
    ----------
    setup : Setup
        The calibration's inputs (:class:`orchestrator.inverse.calibration_stages.Setup`).
    found : Outcome
        What its stages found (:class:`orchestrator.inverse.calibration_stages.Outcome`).
    """
    params, box, chosen, conf = setup.params, found.box, found.chosen, found.confirmation
    names = [p.name for p in params]
    j_before, j_after = conf.objective_before, chosen.objective

    def bounds(lo, hi):
        return {p.name: [p.from_unit(a), p.from_unit(b)] for p, a, b in zip(params, lo, hi)}

    return {
        "scenario": str(setup.base_path),
        "measured": str(setup.objective.measured) if setup.objective.measured is not None else None,
        "parameters": [p.as_dict() for p in params],
        "runs": _runs(setup, found),
        "shift": setup.objective.shift, "seed": setup.seed, "kernel": KERNEL,
        "bounds": {"stage1": bounds(np.zeros(len(params)), np.ones(len(params))), "stage2": bounds(box.lower, box.upper),
                   "stage2_unit": {n: [float(a), float(b)] for n, a, b in zip(names, box.lower, box.upper)}},
        "surrogate_stage1": found.s1.summary(),
        "surrogate": found.fit.surrogate.summary(),
        "channel_surrogates": _channel_surrogates(found.fit.channels),
        "sensitivity": {"tau": box.tau, "u_star": dict(zip(names, map(float, box.u_star))),
                        "objective_at_u_star": float(box.f_star),
                        "range": dict(zip(names, map(float, box.sens["range"]))),
                        "share": dict(zip(names, map(float, box.sens["share"])))},
        "optimum": {"u": dict(zip(names, map(float, found.optimum.u))),
                    "values": dict(zip(names, values_at(params, found.optimum.u))),
                    "predicted_objective": float(found.optimum.value), "confirmed_objective": conf.objective_confirmed,
                    "starts": len(found.optimum.runs)},
        "best_run": _best_run(setup, found),
        "polish": _polish(setup, found.polished),
        "calibrated": {"source": chosen.source, "values": dict(zip(names, found.values)),
                       "file": found.scenario_file.name},
        "objective_before": j_before, "objective_after": j_after,
        "gain": (1.0 - j_after / j_before) if j_before > 0 else None,
        "channels": _channels(found),
        "wall_time_s": None,
    }


def _runs(setup, found) -> dict:
    """``runs``: the designs' sizes, runs without an objective, runs done now and found finished."""
    results = found.design.results
    return {"stage1": setup.n1, "stage2_lhs": setup.n2, "stage2_corners": int(found.corners),
            "total": int(len(found.design.y)), "without_objective": int((~found.design.ok).sum()),
            "done": int(sum(r.done for r in results)), "already_finished": int(sum(r.skipped for r in results))}


def _channel_surrogates(s) -> dict | None:
    """``channel_surrogates``: smoothing and CV errors of the channels' surrogate (``None`` without channels)."""
    if s is None:
        return None
    return {"smoothing": s.smoothing, "cv_rmse": dict(zip(s.names, map(float, s.cv_rmse))),
            "cv_rel": dict(zip(s.names, map(float, s.cv_rel)))}


def _best_run(setup, found) -> dict:
    """``best_run``: J, stage and values of the design's run with the least J."""
    y, U = found.design.y, found.design.U
    i = int(np.nanargmin(y))
    return {"objective": float(y[i]), "stage": 1 if i < setup.n1 else 2,
            "values": dict(zip([p.name for p in setup.params], values_at(setup.params, U[i])))}


def _polish(setup, polished: dict | None) -> dict:
    """``polish``: what the polish found (or why there was none)."""
    if polished is None:
        return {"max_nfev": setup.polish, "done": False,
                "why_not": "polish = 0" if not setup.polish else "a custom run function without a polish_fn"}
    names = [p.name for p in setup.params]
    return {"max_nfev": setup.polish, "done": True, **{k: v for k, v in polished.items() if k not in ("row", "u")},
            "u": dict(zip(names, map(float, polished["u"]))),
            "values": dict(zip(names, values_at(setup.params, polished["u"])))}


def _channels(found) -> dict:
    """``channels``: each channel's nRMSE nominal, calibrated and as the channels' surrogate predicts it."""
    before = channels_of(found.confirmation.nominal)
    after = channels_of(found.chosen.row)
    s = found.fit.channels
    predicted = dict(zip(s.names, map(float, s(found.chosen.u[None])[0]))) if s else {}
    return {c: {"nrmse_before": before.get(c), "nrmse_after": after.get(c), "nrmse_predicted": predicted.get(c)}
            for c in sorted(set(before) | set(after))}


# ======================================================================================
# report.md
# ======================================================================================
def _fmt(v, unit: str) -> str:
    """A value with its unit (gaps in mm)."""
    if unit == "m":
        return f"{1e3 * v:.3f} mm"
    return f"{v:.4g}" + (f" {unit}" if unit not in ("-", "") else "")


def report(s: dict) -> str:
    """The text of ``report.md`` from the summary ``s`` (the content of ``calibration.json``)."""
    lines = [f"# Calibration of {s['scenario']}", "",
             f"Measurement: {s['measured']}; {s['runs']['total']} runs ({s['runs']['stage1']} + "
             f"{s['runs']['stage2_lhs']} + {s['runs']['stage2_corners']} corners).", "",
             f"Objective J: {s['objective_before']:.4g} (nominal) -> {s['objective_after']:.4g} (calibrated, "
             f"{s['calibrated']['source']}); gain {100 * (s['gain'] or 0):.1f} %.", "",
             f"Surrogate (thin-plate spline, smoothing by {CV_FOLDS}-fold CV): stage 1 CV RMSE "
             f"{s['surrogate_stage1']['cv_rmse']:.3g} ({100 * s['surrogate_stage1']['cv_rel']:.1f} % of the spread "
             f"of J), all runs {s['surrogate']['cv_rmse']:.3g} ({100 * s['surrogate']['cv_rel']:.1f} %).", "",
             f"Surrogate optimum: predicted J = {s['optimum']['predicted_objective']:.4g}, "
             f"simulated J = {s['optimum']['confirmed_objective']:.4g}.", "",
             (f"Polish (least squares on real runs, from the {s['polish']['start']}): {s['polish']['runs']} runs in "
              f"{s['polish']['iterations']} parallel sweeps, J = {s['polish']['objective']:.4g}; sum of squared "
              f"residuals {s['polish']['cost_start']:.4g} -> {s['polish']['cost']:.4g}." if s["polish"]["done"] else
              f"No polish ({s['polish']['why_not']})."), "",
             "| parameter | stage-1 bounds | narrowed bounds | sensitivity share | calibrated |",
             "|---|---|---|---|---|"]
    for p in s["parameters"]:
        n, u = p["name"], p["unit"]
        b1, b2 = s["bounds"]["stage1"][n], s["bounds"]["stage2"][n]
        lines.append(f"| {n} | {_fmt(b1[0], u)} - {_fmt(b1[1], u)} | {_fmt(b2[0], u)} - {_fmt(b2[1], u)} | "
                     f"{100 * s['sensitivity']['share'][n]:.1f} % | {_fmt(s['calibrated']['values'][n], u)} |")
    lines += ["", "| channel | nRMSE nominal | nRMSE calibrated |", "|---|---|---|"]
    for c, v in s["channels"].items():
        b, a = v["nrmse_before"], v["nrmse_after"]
        lines.append(f"| {c} | {b:.3g} | {a:.3g} |" if b is not None and a is not None else f"| {c} | | |")
    lines += ["", "Plots: " + ", ".join(s.get("plots", [])), ""]
    return "\n".join(lines)


# ======================================================================================
# Plots
# ======================================================================================
def plots(setup, found) -> list[Path]:
    """Draw the CV, sensitivity and (with a measurement) signal plots into ``OUT``; returns their files."""
    out, first, design = setup.out, found.first, found.design
    files = [plot_cv(out / "calibration_cv.png", found.s1, found.fit.surrogate, first.y[first.ok],
                     design.y[design.ok]),
             plot_sensitivity(out / "calibration_sensitivity.png", [p.name for p in setup.params], found.box)]
    if setup.objective.target is not None:
        files.append(plot_signals(out / "calibration_signals.png", setup.objective.target, _shown(setup, found),
                                  found.chosen.source))
    return files


def _shown(setup, found) -> dict:
    """The runs whose signals are plotted: label -> (runs folder, run id)."""
    conf, chosen = found.confirmation, found.chosen
    runs = setup.out / "confirm" / "runs"
    shown = {"nominal": (runs, conf.nominal["run_id"]), "surrogate optimum": (runs, conf.optimum["run_id"])}
    if chosen.signals_at is not None and chosen.source != "surrogate optimum":
        shown[f"calibrated ({chosen.source})"] = chosen.signals_at
    return shown


def plot_cv(path: Path, s1, s, y1: np.ndarray, y: np.ndarray) -> Path:
    """Held-out predictions against simulated J, of stage 1's surrogate ``s1`` (J ``y1``) and of ``s`` (J ``y``)."""
    from orchestrator.results.plots import _plt, save

    fig, axes = _plt().subplots(1, 2, figsize=(10, 4.5))
    for ax, sur, yy, title in ((axes[0], s1, y1, "stage 1"), (axes[1], s, y, "all runs")):
        pred = sur.cv_pred[:, 0]
        ax.loglog(yy, pred, ".", ms=3, alpha=0.6)
        lim = [min(yy.min(), pred.min()), max(yy.max(), pred.max())]
        ax.plot(lim, lim, "k-", lw=0.8)
        ax.set_xlabel("objective J, simulated [-]")
        ax.set_ylabel("J, surrogate held-out prediction [-]")
        ax.set_title(f"{title}: {len(yy)} runs, CV RMSE {sur.cv_rmse[0]:.3g} ({100 * sur.cv_rel[0]:.1f} % of spread)")
        ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    save(fig, path)
    return path


def plot_sensitivity(path: Path, names: list[str], box) -> Path:
    """The sensitivity (profile range) per parameter and the narrowed bounds of stage 2 (a Narrowing ``box``)."""
    from orchestrator.results.plots import _plt, save

    fig, axes = _plt().subplots(1, 2, figsize=(11, 4.5))
    axes[0].bar(names, box.sens["range"])
    axes[0].set_ylabel("range of the surrogate's profile [J]")
    axes[0].set_title("sensitivity at the stage-1 optimum")
    axes[0].tick_params(axis="x", rotation=45)
    axes[1].barh(names, np.asarray(box.upper) - np.asarray(box.lower), left=box.lower)
    axes[1].set_xlim(0, 1)
    axes[1].set_xlabel("unit coordinate")
    axes[1].set_title("narrowed bounds (stage 2)")
    for ax in axes:
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    save(fig, path)
    return path


def plot_signals(path: Path, target, shown: dict, source: str) -> Path:
    """Measured against simulated signals; ``shown``: label -> (runs folder, run id) of saved signals."""
    from orchestrator.results.plots import _plt, save

    ids = [i for i in SIGNAL_PLOT_IDS if i in target.measured.channels] or list(target.measured.channels)[:6]
    sims = {}
    for label, (runs_dir, rid) in shown.items():
        f = runs_dir / rid / SIGNALS_FILE
        if f.is_file():
            data = np.load(f)
            sims[label] = target.compare(data["t"], {k: data[k] for k in data.files if k != "t"}).simulated
    fig, axes = _plt().subplots(len(ids), 1, figsize=(8, 1.8 * len(ids) + 0.6), sharex=True, squeeze=False)
    t = target.measured.t
    for ax, sid in zip(axes[:, 0], ids):
        ax.plot(t, target.measured.channels[sid], "k-", lw=0.8, label="measured")
        for label, sim in sims.items():
            ax.plot(t, sim[sid], lw=1.0, label=label)
        ax.set_ylabel(sid)
        ax.grid(True, alpha=0.3)
    axes[0, 0].legend(fontsize="small", ncol=3)
    axes[-1, 0].set_xlabel("measured time [s]")
    if source == "best run":
        axes[0, 0].set_title("(the calibrated scenario is the best run of the design; its optimum is shown)")
    fig.tight_layout()
    save(fig, path)
    return path
