"""The diagnosis report: report.md and its plots (overlays per sensor group, residual bars).

It reads the typed result, :class:`orchestrator.inverse.diagnosis.Diagnosis`, and leads
with the verdict and its evidence in plain words (:func:`_verdict_lines`), then the
residual before/after per channel, the nuisance estimates, the named causes' intervals (or,
for a ``none`` answer, what the record resolves), the candidates, the validation passages and the variants left out.

The plots are the report's slowest part (~0.5 s each, 3.5 s for the default layout's seven,
after the runs, with every worker idle): given the diagnosis's executor, :func:`write_report`
has its workers draw them, each handed only its channels' arrays, and writes the PNG bytes
they return (so a cluster's workers need no access to the output folder).
"""
from __future__ import annotations

import concurrent.futures as cf
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from orchestrator.inverse.diagnosis import Diagnosis
from orchestrator.results.plots import _plt, png_bytes

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


def draw_png(plot, *args) -> bytes:
    """``plot(*args)`` as PNG bytes (what a worker of :func:`write_report` runs)."""
    return png_bytes(plot(*args))


def _channels_of(target, before, after, layout, ids: list) -> tuple:
    """The arguments of :func:`plot_overlays` cut down to the channels ``ids`` (what a worker needs of them)."""
    def cmp(c):
        return SimpleNamespace(simulated={k: c.simulated[k] for k in ids}, channels={k: c.channels[k] for k in ids})

    b = cmp(before)
    return (SimpleNamespace(measured=SimpleNamespace(t=target.measured.t,
                                                     channels={k: target.measured.channels[k] for k in ids})),
            b, b if after is before else cmp(after),
            SimpleNamespace(ids=list(ids), groups={k: layout.groups[k] for k in ids},
                            types={k: layout.types[k] for k in ids}))


def _figures(target, before, after, layout) -> list[tuple[str, object, tuple]]:
    """(file name, plot function, its arguments) of the report's plots."""
    groups = sorted({layout.groups[k] for k in before.channels})
    out = []
    for g in groups:
        ids = [k for k in layout.ids if layout.groups[k] == g and k in before.channels]
        out.append((f"overlay_{g}.png", plot_overlays, (*_channels_of(target, before, after, layout, ids), g)))
    bars = [SimpleNamespace(channels={k: {"nrmse": c.channels[k]["nrmse"]} for k in before.channels})
            for c in (before, after)]
    return out + [("residuals.png", plot_residual_bars, tuple(bars))]


def _draw_all(out_dir: Path, figures: list, executor) -> None:
    """Write every figure: drawn by ``executor``'s workers when given (here if it cannot take them)."""
    futures = None
    if executor is not None:
        try:
            futures = [executor.submit(draw_png, plot, *args) for _, plot, args in figures]
        except (cf.BrokenExecutor, RuntimeError):   # shut down or broken: draw here
            futures = None
    for i, (name, plot, args) in enumerate(figures):
        (out_dir / name).write_bytes(futures[i].result() if futures is not None else draw_png(plot, *args))


def write_report(out_dir: Path, result: Diagnosis, target, before, after, layout, executor=None) -> Path:
    """Write the plots and ``report.md`` into ``out_dir``; returns the report's path.

    ``result`` is the diagnosis; ``target`` the measured passage
    (:class:`orchestrator.inverse.objective.Target`); ``before`` and ``after`` the nominal
    and the extended model's comparisons with it; ``layout`` the sensor layout;
    ``executor`` (optional) draws the plots on its workers (module doc).
    """
    out_dir = Path(out_dir)
    figures = _figures(target, before, after, layout)
    _draw_all(out_dir, figures, executor)
    lines = (_verdict_lines(result) + _baseline_lines(result, before, after) + _nuisance_lines(result)
             + _interval_lines(result) + _resolution_lines(result) + _cause_lines(result) + _dropped_lines(result))
    if result.validation:
        lines += ["## Validation at other speeds", "", "| file | speed [m/s] | J before | J after | gain |",
                  "|---|---|---|---|---|"]
        for v in result.validation:
            lines.append(f"| {v.file} | {v.speed:.4g} | {v.objective_before:.4g} | "
                         f"{v.objective_after:.4g} | {100 * v.gain:.1f} % |")
        lines.append("")
    lines += ["Plots: " + ", ".join(f"`{name}`" for name, _, _ in figures) + ".", ""]
    path = out_dir / "report.md"
    path.write_text("\n".join(lines), encoding="utf-8")
    return path


def _label(c) -> str:
    return c.cause + ("" if c.sleeper is None else f" at sleeper {c.sleeper}")


def _share(s: dict) -> str:
    """The share of the explainable misfit a cause removed, and what it was measured against
    (``significance.share_of``, :func:`orchestrator.inverse.significance.assess`)."""
    x = s.get("share_of_explainable_misfit")
    if x is None:
        return "an undefined share of the misfit above the noise"
    j_noise = s["objective_noise"]
    j_floor = s.get("objective_floor", j_noise)
    step = j_floor > j_noise   # the floor holds the model's own time-step error (significance.floor_objective)
    if s.get("share_of") == "noise_margin":
        what = "the floor's (noise and the model's step error)" if step else "the noise objective's"
        return f"{100 * x:.0f} % of {what} margin, {s['thresholds']['none_margin']:g} x {j_floor:.4g}"
    if step:
        return f"{100 * x:.0f} % of the misfit above the noise and the model's own step error (J {j_floor:.4g})"
    return f"{100 * x:.0f} % of the misfit above the noise"


def _refit_words(c) -> str:
    """A named cause refitted with the other one (diagnose step 5b) or after the nuisance values' refit (step 5d):
    from which values, and J before -> after."""
    out = ""
    r = c.evidence.get("refit")
    if r:
        out += (f"; refitted on the model with the other cause (named at {_fmt(r['parameters_round'])}): the extended "
                f"model's J {r['objective_before']:.4g} → {r['objective_after']:.4g}")
    r = c.evidence.get("refit_nuisance")
    if r:
        out += (f"; fitted again with the nuisance values refitted (from {_fmt(r['parameters_before'])}): the extended "
                f"model's J {r['objective_before']:.4g} → {r['objective_after']:.4g}")
    return out


def _verdict_lines(result: Diagnosis) -> list[str]:
    """The head: the verdict and its evidence in plain words."""
    a = result.answer
    lines = [f"# Diagnosis of {result.measured}", "",
             f"Scenario `{result.scenario}`; {result.runs} runs in {result.wall_seconds:.0f} s.", "", "## Verdict", ""]
    if a.kind == "named":
        lines.append(f"**named: {' + '.join(_label(c) for c in a.causes)}**. In plain words: {a.reason}")
        for c in a.causes:
            s = c.evidence.get("significance", {})
            amb = (c.ambiguity or {}).get("candidates", [])
            lines += ["", f"- {_label(c)}: {_fmt(c.parameters)}; J {s.get('objective_reference', float('nan')):.4g}"
                          f" → {c.objective:.4g} (gain {100 * c.gain:.1f} %, "
                          f"{_share(s)}); "
                          f"ΔBIC on {s.get('n_eff', 0):.0f} effective samples {s.get('delta_bic_eff', 0):.3g}"
                          + (f"; cannot be told apart from {', '.join(amb[1:])}" if len(amb) > 1 else "")
                          + (f"; {c.ambiguity['open_beyond']}" if (c.ambiguity or {}).get("open_beyond") else "")
                          + _refit_words(c) + "."]
    else:
        lines.append(f"**{a.kind}**: {a.reason}.")
    if a.where:
        w = a.where
        lines += ["", f"Where the remaining residual lives: channels "
                      f"{', '.join(c['id'] for c in w['channels']) or '-'}; time {w['time_window'][0]:.4f}–"
                      f"{w['time_window'][1]:.4f} s (wheel at x = {w['wheel_position'][0]:.2f}–"
                      f"{w['wheel_position'][1]:.2f} m, nearest sleepers {w['sleepers_in_window']}, largest at "
                      f"sleeper {w['sleeper_nearest_peak']}); channels on sleepers {w['sleepers_of_channels']}"
                      + (f"; {w['edge']}" if w.get("edge") else "") + f"; frequency band {w['band_hz'][0]:.0f}–"
                      f"{w['band_hz'][1]:.0f} Hz (peak {w['peak_hz']:.0f} Hz)."]
        se = w.get("model_step_error")
        if se:
            lines += ["", f"The model's own time-step error (the reference at half its step, "
                          f"{0.5 * se['step']:g} s, against it at {se['step']:g} s): J {se['objective']:.3g}; by group "
                          + ", ".join(f"{g} {v:.3g}" for g, v in sorted(se['groups'].items(), key=lambda kv: -kv[1]))
                          + ". No catalogue cause can remove it (every variant runs at the same step)."]
    return lines + [""]


def _nuisance_lines(result: Diagnosis) -> list[str]:
    """The nuisance estimates: how the measurement / vehicle differs from the scenario (never a track cause)."""
    nz = result.nuisance
    if not nz:
        return ["## Nuisance parameters", "", "No nuisance stage ran: the causes were fitted on the nominal scenario.",
                ""]
    lines = ["## Nuisance parameters", "", "The measurement / vehicle differs from the scenario by:", "",
             "| parameter | scenario | estimate | 90 % interval | identifiable |", "|---|---|---|---|---|"]
    values, nominal = nz.get("values", {}), nz.get("nominal", {})
    intervals, ident = nz.get("intervals", {}), nz.get("identifiable", {})
    for k, v in values.items():
        lines.append(f"| {k} | {_fmt(nominal.get(k, ''))} | {_fmt(v)} | {_fmt(intervals.get(k, ''))} | "
                     f"{ident.get(k, '')} |")
    if nz.get("channel_gains"):
        lines += ["", "Sensor gains: " + _fmt(nz["channel_gains"]) + "."]
    lines += [""] + [f"- {n}" for n in nz.get("notes", [])]
    return lines + [""]


def _interval_lines(result: Diagnosis) -> list[str]:
    """The named causes' 90 % intervals, identifiability and the sensors that would pin them."""
    causes = [c for c in result.answer.causes if c.uncertainty]
    if not causes:
        return []
    lines = ["## Intervals of the named causes (90 %)", "",
             "| cause | entry | fitted | 90 % interval | identifiable |", "|---|---|---|---|---|"]
    for c in causes:
        u = c.uncertainty
        name, vals = next(iter(c.parameters.items()))
        vals = vals if isinstance(vals, list) else [vals]
        for i, (v, iv, ok) in enumerate(zip(vals, u["intervals"], u["identifiable"])):
            lines.append(f"| {_label(c)} | {name}[{i}] | {v:.4g} | {iv[0]:.4g}–{iv[1]:.4g} | "
                         f"{'yes' if ok else 'no'} |")
        if u["pin_with"]:
            lines.append(f"\n{_label(c)}: to pin what the data leave open, add {'; '.join(u['pin_with'])}.\n")
    return lines + [""]


def _resolution_lines(result: Diagnosis) -> list[str]:
    """A ``none`` answer's tables of what the record resolves (:mod:`orchestrator.inverse.resolution`): per
    candidate the least effect that would not have passed for noise, voids by shape, the others either side."""
    limits = result.answer.resolution
    if not limits:
        return []
    by: dict[tuple, dict] = {}
    for r in limits:
        by.setdefault((r["cause"], r["sleeper"]), {})[r["proxy"]] = r
    lines = ["## What this record resolves", "",
             "The least effect that would have lifted the residual above the noise level, per candidate screened "
             "(`>`: not within the farthest magnitude screened). First order, on this record's noise: an upper "
             "bound of what can hide in it; smaller effects may still be named. Sleepers not listed were not "
             "screened.", ""]
    voids = {k: v for k, v in by.items() if k[0] == "ballast_void"}
    if voids:
        shapes = list(dict.fromkeys(p for v in voids.values() for p in v))
        lines += ["| void under sleeper: peak gap [mm] | " + " | ".join(shapes) + " |", "|---|" + "---|" * len(shapes)]
        lines += [f"| {k[1]} | " + " | ".join(_limit_cell(v.get(p)) for p in shapes) + " |" for k, v in voids.items()]
        lines.append("")
    rest = {k: v for k, v in by.items() if k[0] != "ballast_void"}
    if rest:
        lines += ["| cause | sleeper | nominal | at or below | at or above |", "|---|---|---|---|---|"]
        for (cause, sleeper), v in rest.items():
            below = next((r for p, r in v.items() if p in ("softer", "lower")), None)
            above = next((r for p, r in v.items() if p in ("stiffer", "higher")), None)
            any_ = below or above
            lines.append(f"| {cause} | {'' if sleeper is None else sleeper} | "
                         f"{_in_units(any_['nominal'], any_['unit'])} | {_limit_cell(below)} | {_limit_cell(above)} |")
        lines.append("")
    return lines


def _in_units(value: float, unit: str) -> str:
    """A magnitude in the report's units: mm for m, mrad (named) for rad, others as they are."""
    f, name = {"m": (1e3, ""), "rad": (1e3, " mrad")}.get(unit, (1.0, ""))
    return f"{f * value:.3g}{name}"


def _limit_cell(r: dict | None) -> str:
    """One limit (:func:`_in_units`), ``> end`` where not resolved within the screened range."""
    if r is None:
        return ""
    return _in_units(r["limit"], r["unit"]) if r["limit"] is not None else "> " + _in_units(r["screened_to"], r["unit"])


def _dropped_lines(result: Diagnosis) -> list[str]:
    """The variants left out and why."""
    if not result.dropped:
        return []
    lines = ["## Variants left out", "", "| variant | stage | reason |", "|---|---|---|"]
    lines += [f"| {d['variant']} | {d['stage']} | {d['reason']} |" for d in result.dropped]
    return lines + [""]


def _baseline_lines(result: Diagnosis, before, after) -> list[str]:
    """What the simulation gets wrong, and the residual before/after per channel (``before``/``after``: the
    nominal and the extended model's comparisons)."""
    b = result.baseline
    lines = ["## What the simulation gets wrong", "",
             f"Objective of the nominal model J = {b.objective:.4g} (noise alone would give "
             f"{_noise_j(result):.4g}). By group (mean nRMSE): " +
             ", ".join(f"{g} {v:.3g}" for g, v in b.where["groups"].items()) + ".", "",
             "Sleepers (mean nRMSE of their sensors): " +
             ", ".join(f"{k}: {v:.3g}" for k, v in b.where["sleepers"].items()) + ".", "",
             "| channel | nRMSE before | nRMSE after | gain | largest residual at [s] "
             "| 80 % of residual energy in [s] |",
             "|---|---|---|---|---|---|"]
    for k, v in before.channels.items():
        a = after.channels[k]["nrmse"]
        lines.append(f"| {k} | {v['nrmse']:.4g} | {a:.4g} | {100 * result.gain.channels.get(k, 0.0):.1f} % | "
                     f"{v['t_peak']:.4f} | {v['window'][0]:.4f}–{v['window'][1]:.4f} |")
    return lines + [""]


def _noise_j(result: Diagnosis) -> float:
    for c in result.answer.causes + result.causes:
        s = c.evidence.get("significance")
        if s:
            return s["objective_noise"]
    return float("nan")


def _looked_further(settings: dict) -> str:
    """The sentence saying round 1 looked beyond ``sensor_reach`` (diagnose step 3b), or "" when it did not."""
    if not settings.get("looked_further"):
        return ""
    return (f"Round 1 named nothing near the sensors above the noise, so it also looked up to "
            f"{settings.get('far_reach')} sleepers beyond them (step 3b).")


def _cause_lines(result: Diagnosis) -> list[str]:
    """The table of candidates and the extended scenario's gain."""
    lines = ["", "## Candidates (per round, best first)", "",
             "| round | cause | sleeper | stage | parameters | J | gain | ΔBIC_eff vs best | rule |",
             "|---|---|---|---|---|---|---|---|---|"]
    far = _looked_further(result.settings)
    if far:
        lines[1:1] = ["", far]
    for c in result.causes:
        e = c.evidence
        sig = e.get("significance")
        rule = "" if sig is None else ("passes" if sig["passes"] else "; ".join(sig["reasons"]))
        d = e.get("delta_bic_eff_vs_best")
        lines.append(f"| {e.get('round', 1)} | {c.cause} | {'' if c.sleeper is None else c.sleeper} | {e['stage']} | "
                     f"{_fmt(c.parameters)} | {c.objective:.4g} | {100 * c.gain:.1f} % | "
                     f"{'' if d is None else f'{d:.4g}'} | {rule} |")
    lines += ["", f"Extended scenario: `{result.extended_scenario}`. Total gain "
                  f"{100 * result.gain.total:.1f} %.", ""]
    return lines
