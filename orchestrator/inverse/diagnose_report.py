"""The diagnosis report: report.md and its plots (overlays per sensor group, residual bars).

It reads the typed result, :class:`orchestrator.inverse.diagnosis.Diagnosis`.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from orchestrator.inverse.diagnosis import Diagnosis
from orchestrator.results.plots import _plt, save

UNITS = {"pressure": ("kPa", 1e-3), "displacement": ("mm", 1e3), "acceleration": ("m/s²", 1.0),
         "strain": ("µε", 1e6)}


def plot_overlays(target, before, after, layout, group: str):
    """Measured, nominal and extended signals of one sensor group (one panel per channel)."""
    plt = _plt()
    ids = [k for k in layout.ids if layout.groups[k] == group and k in before.channels]
    fig, axes = plt.subplots(len(ids), 1, figsize=(9, 1.9 * len(ids) + 0.6), sharex=True, squeeze=False)
    t = target.measured.t
    for ax, k in zip(axes[:, 0], ids):
        unit, f = UNITS[layout.types[k]]
        ax.plot(t, f * target.measured.channels[k], c="0.35", lw=0.8, label="measured")
        ax.plot(t, f * before.simulated[k], c="C0", lw=1.0, label=f"nominal (nRMSE {before.channels[k]['nrmse']:.3f})")
        if after is not before:
            ax.plot(t, f * after.simulated[k], c="C3", lw=1.0, ls="--",
                    label=f"extended (nRMSE {after.channels[k]['nrmse']:.3f})")
        ax.set_ylabel(f"{k} [{unit}]")
        ax.legend(fontsize=7, loc="upper right")
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("measured time [s]")
    fig.suptitle(f"group {group}: measured vs simulated")
    fig.tight_layout()
    return fig


def plot_residual_bars(before, after):
    """nRMSE per channel, nominal vs extended model."""
    plt = _plt()
    ids = list(before.channels)
    x = np.arange(len(ids))
    fig, ax = plt.subplots(figsize=(max(6, 0.45 * len(ids) + 2), 3.6))
    ax.bar(x - 0.2, [before.channels[k]["nrmse"] for k in ids], 0.4, label="nominal")
    ax.bar(x + 0.2, [after.channels[k]["nrmse"] for k in ids], 0.4, label="extended")
    ax.set_xticks(x, ids, rotation=90)
    ax.set_ylabel("nRMSE [-]")
    ax.legend()
    ax.grid(alpha=0.3, axis="y")
    fig.tight_layout()
    return fig


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, list):
        return "[" + ", ".join(_fmt(x) for x in v) + "]"
    if isinstance(v, dict):
        return ", ".join(f"{k} = {_fmt(x)}" for k, x in v.items())
    return str(v)


def write_report(out_dir: Path, result: Diagnosis, target, before, after, layout) -> Path:
    """Write the plots and ``report.md`` into ``out_dir``; returns the report's path.

    ``result`` is the diagnosis; ``target`` the measured passage
    (:class:`orchestrator.inverse.objective.Target`); ``before`` and ``after`` the nominal
    and the extended model's comparisons with it; ``layout`` the sensor layout.
    """
    out_dir = Path(out_dir)
    groups = sorted({layout.groups[k] for k in before.channels})
    for g in groups:
        save(plot_overlays(target, before, after, layout, g), out_dir / f"overlay_{g}.png")
    save(plot_residual_bars(before, after), out_dir / "residuals.png")
    lines = _baseline_lines(result, before) + _cause_lines(result)
    if result.validation:
        lines += ["## Validation at other speeds", "", "| file | speed [m/s] | J before | J after | gain |",
                  "|---|---|---|---|---|"]
        for v in result.validation:
            lines.append(f"| {v.file} | {v.speed:.4g} | {v.objective_before:.4g} | "
                         f"{v.objective_after:.4g} | {100 * v.gain:.1f} % |")
        lines.append("")
    lines += ["Plots: " + ", ".join(f"`overlay_{g}.png`" for g in groups) + ", `residuals.png`.", ""]
    path = out_dir / "report.md"
    path.write_text("\n".join(lines), encoding="utf-8")
    return path


def _baseline_lines(result: Diagnosis, before) -> list[str]:
    """The report's head and what the simulation gets wrong (``before``: the nominal model's comparison)."""
    b = result.baseline
    lines = [f"# Diagnosis of {result.measured}", "",
             f"Scenario `{result.scenario}`; {result.runs} runs in {result.wall_seconds:.0f} s.", "",
             "## What the simulation gets wrong", "",
             f"Objective of the nominal model J = {b.objective:.4g} (noise-only would give about the noise "
             f"share of each channel). By group (mean nRMSE): " +
             ", ".join(f"{g} {v:.3g}" for g, v in b.where["groups"].items()) + ".", "",
             "Sleepers (mean nRMSE of their sensors): " +
             ", ".join(f"{k}: {v:.3g}" for k, v in b.where["sleepers"].items()) + ".", "",
             "| channel | nRMSE | RMSE | largest residual at [s] | 80 % of residual energy in [s] |",
             "|---|---|---|---|---|"]
    for k, v in before.channels.items():
        lines.append(f"| {k} | {v['nrmse']:.4g} | {v['rmse']:.4g} | {v['t_peak']:.4f} | "
                     f"{v['window'][0]:.4f}–{v['window'][1]:.4f} |")
    return lines


def _cause_lines(result: Diagnosis) -> list[str]:
    """The report's named cause, its table of candidates and the extended scenario's gain."""
    named = result.named_cause
    lines = ["", "## Named cause", ""]
    if named.cause == "none":
        e = named.evidence
        lines.append(f"**none**: {e['reason']} (best candidate {e['best_candidate']}, "
                     f"BIC gain {e['delta_bic_vs_nominal']:.3g} <= {e['threshold']}).")
    else:
        where = f" at sleeper {named.sleeper}" if named.sleeper is not None else ""
        lines.append(f"**{named.cause}{where}**: {_fmt(named.parameters)}; objective {named.objective:.4g}, "
                     f"gain {100 * named.gain:.1f} %; cannot be told apart from: "
                     f"{', '.join(named.evidence['indistinguishable_from']) or 'none'}.")
    lines += ["", "## Candidates (best first)", "",
              "| cause | sleeper | stage | parameters | J | gain | ΔBIC vs nominal |", "|---|---|---|---|---|---|---|"]
    for c in result.causes:
        e = c.evidence
        sleeper = "" if c.sleeper is None else c.sleeper
        lines.append(f"| {c.cause} | {sleeper} | {e['stage']} | {_fmt(c.parameters)} | "
                     f"{c.objective:.4g} | {100 * c.gain:.1f} % | {e['delta_bic_vs_nominal']:.4g} |")
    lines += ["", f"Extended scenario: `{result.extended_scenario}`. Total gain "
                  f"{100 * result.gain.total:.1f} %.", ""]
    return lines
