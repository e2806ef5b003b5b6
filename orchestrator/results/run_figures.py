"""The figures of ``turnout run``: drawn from plain arrays (by the figure process of
:class:`orchestrator.results.figure_writer.FigureWriter`, which imports this module and
:mod:`orchestrator.results.plots` while the co-simulation runs).

``signals`` is any object with the run's ``t``, ``x``, ``z``, ``Fz``, ``rail_z`` and ``parts``
(:func:`plotted_signals`: those of a :class:`orchestrator.cosim.master.CosimResult`, without
the track model and the records it may hold).
"""
from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np

from orchestrator.results import plots
from orchestrator.results.plots_layout import plot_layout

SIGNALS = ("t", "x", "z", "Fz", "rail_z", "parts")
# what track_results reads of an Analysis: only these go to the figure process (its meta also holds
# the whole histories and the loads with their rail points, which would drag the model along)
TRACK_ARRAYS = ("rail_x", "rail_M_min", "rail_M_max", "rail_w_at_max", "rail_M_at_max", "sleeper_y",
                "sleeper_M_min", "sleeper_M_max", "sleeper_w_at_max", "sleeper_M_at_max", "ballast_y",
                "ballast_p_max", "x_transition", "wheel_y")
TRACK_META = ("crossing_rail", "transition_sleeper")
TRACK_SCALARS = ("time_max_rail_moment", "time_max_sleeper_moment")


def plotted_signals(res) -> SimpleNamespace:
    """The arrays of ``res`` the figures read (what is sent to the figure process)."""
    return SimpleNamespace(**{k: getattr(res, k) for k in SIGNALS})


def plotted_analysis(an) -> tuple[dict, dict, dict]:
    """``(arrays, meta, scalars)`` of an Analysis as :func:`track_results` reads them, nothing more."""
    return ({k: an.arrays[k] for k in TRACK_ARRAYS}, {k: an.meta[k] for k in TRACK_META},
            {k: an.scalars[k] for k in TRACK_SCALARS})


def track_results(out_dir: Path, name: str, a: dict, meta: dict, t: dict) -> None:
    """envelopes.png and moments.png from the analysis (``a``, ``meta``, ``t``: an
    :class:`orchestrator.results.analysis.Analysis`'s ``arrays``, ``meta`` and ``scalars``)."""
    rail_name, sl_name = meta["crossing_rail"], f"sleeper_{meta['transition_sleeper']}"
    plots.save(plots.plot_envelopes(a["rail_x"], np.stack([a["rail_M_min"], a["rail_M_max"]]),
                                    a["sleeper_y"], np.stack([a["sleeper_M_min"], a["sleeper_M_max"]]),
                                    a["ballast_y"], a["ballast_p_max"], rail_name, sl_name),
               out_dir / "envelopes.png")
    inst_r = {f"t = {t['time_max_rail_moment']:.4f} s (max rail moment)":
              _body_line(a["rail_x"], a["rail_w_at_max"], a["rail_M_at_max"])}
    inst_s = {f"t = {t['time_max_sleeper_moment']:.4f} s (max sleeper moment)":
              _body_line(a["sleeper_y"], a["sleeper_w_at_max"], a["sleeper_M_at_max"])}
    plots.save(plots.plot_body_lines(inst_r, inst_s, f"{name}: instants of maximum moment",
                                     rail_name, f"{sl_name} (crossing transition)",
                                     marks_rail=[a["x_transition"][0]],
                                     marks_sleeper=list(a["wheel_y"])), out_dir / "moments.png")


def _body_line(coord, w, moment) -> SimpleNamespace:
    """A body's deflection and moment along it as :func:`plots.plot_body_lines` reads them (the
    fields of a ``track.post.BodyResponse``: importing :mod:`track.post` loads scipy.sparse, 0.13 s
    of the figure process's last job, which the run waits for)."""
    return SimpleNamespace(coord=coord, w=w, moment=moment)


def contact_path(out_dir: Path, lay, res, geometry: dict) -> None:
    """contact_path.png: the first wheel at the nose, its contact path and vertical trajectory."""
    i = ["left", "right"].index(lay.crossing_side)      # wheels alternate left, right from the front
    fig = plots.plot_contact_path(res.x[:, i], geometry["eta"][:, i], res.z[:, i], res.parts[:, i], lay.x_tcp,
                                  f"wheel {i + 1}")
    plots.save(fig, out_dir / "contact_path.png")


def layout(out_dir: Path, lay) -> None:
    """layout.png: the track layout (needs nothing from the co-simulation: drawn during it)."""
    plots.save(plot_layout(lay), out_dir / "layout.png")


def contact_forces(out_dir: Path, name: str, res) -> None:
    """contact_forces.png: each wheel's contact force over time."""
    plots.save(plots.plot_time_series(res.t, {f"wheel {i + 1}": 1e-3 * res.Fz[:, i] for i in range(res.Fz.shape[1])},
                                      "contact force [kN]", f"{name}: wheel-rail contact forces"),
               out_dir / "contact_forces.png")


def displacements(out_dir: Path, name: str, res) -> None:
    """displacements.png: each wheel's and the rail's under it vertical displacement over time."""
    wheels = range(res.Fz.shape[1])
    series = {f"wheel {i + 1}": 1e3 * res.z[:, i] for i in wheels}
    series.update({f"rail under wheel {i + 1}": 1e3 * res.rail_z[:, i] for i in wheels})
    plots.save(plots.plot_time_series(res.t, series, "vertical displacement [mm]",
                                      f"{name}: wheel and rail displacement"), out_dir / "displacements.png")
