"""The diagnosis report's plots (orchestrator.inverse.diagnose_report): drawn by an executor's workers and
written from the PNG bytes they return, or drawn here. No simulation."""
import concurrent.futures as cf
import multiprocessing
from types import SimpleNamespace

import numpy as np

from orchestrator.inverse import diagnose_report as report


def _inputs():
    """A measured passage of three channels in two groups, and a nominal and an extended comparison."""
    t = np.linspace(0.0, 0.1, 300)
    meas = {"A1": 1e5 * np.sin(40 * t), "A2": 8e4 * np.cos(40 * t), "B1": 0.3 * np.sin(90 * t)}
    target = SimpleNamespace(measured=SimpleNamespace(t=t, channels=meas))

    def cmp(scale):
        return SimpleNamespace(simulated={k: scale * v for k, v in meas.items()},
                               channels={k: {"nrmse": abs(1 - scale) + 0.01 * i} for i, k in enumerate(meas)})

    layout = SimpleNamespace(ids=["A1", "A2", "B1"], groups={"A1": "A", "A2": "A", "B1": "B"},
                             types={"A1": "pressure", "A2": "pressure", "B1": "acceleration"})
    return target, cmp(0.9), cmp(0.98), layout


C0 = (0x1F, 0x77, 0xB4)   # matplotlib's first cycle colour: the nominal curve and the nominal residual bars


def _has_colour(png: bytes, rgb: tuple) -> bool:
    """Whether a pixel of the PNG has exactly the colour ``rgb`` (0-255; anti-aliased edges differ, line cores not)."""
    import io

    import matplotlib.image as mpimg
    img = np.round(mpimg.imread(io.BytesIO(png), format="png")[..., :3] * 255).astype(int)
    return bool((img == np.array(rgb)).all(axis=-1).any())


def test_plots_drawn_by_workers_are_the_plots_drawn_here(tmp_path):
    """Consistency check (two paths of ours): each figure a worker process draws from the channels it is
    handed is byte for byte the one drawn here from the whole comparison (the same matplotlib, no time
    stamp in the PNG), one file per group and the residual bars; a shut-down executor draws here."""
    target, before, after, layout = _inputs()
    figures = report._figures(target, before, after, layout)
    assert [name for name, _, _ in figures] == ["overlay_A.png", "overlay_B.png", "residuals.png"]
    here, there, fallback = tmp_path / "here", tmp_path / "there", tmp_path / "fallback"
    for d in (here, there, fallback):
        d.mkdir()
    report._draw_all(here, figures, None)
    with cf.ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as ex:
        report._draw_all(there, figures, ex)
    report._draw_all(fallback, figures, ex)    # shut down: RuntimeError on submit, drawn here
    for name, _, _ in figures:
        png = (here / name).read_bytes()
        # a whole PNG (10 kB is under any figure of this size: empty axes of one panel are 12.8 kB, measured,
        # so this rules out a truncated file, not an empty plot) ...
        assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000
        assert _has_colour(png, C0)   # ... with curves or bars in it: the nominal curve / bars colour is drawn
        assert (there / name).read_bytes() == png and (fallback / name).read_bytes() == png
    # cut down to a group's channels (what goes to a worker), the figure is the one of the whole comparison
    for g in ("A", "B"):
        full = report.draw_png(report.plot_overlays, target, before, after, layout, g)
        assert (here / f"overlay_{g}.png").read_bytes() == full
    assert (here / "residuals.png").read_bytes() == report.draw_png(report.plot_residual_bars, before, after)
    t_a, b_a, _, lay_a, g = figures[0][2]
    assert g == "A" and sorted(t_a.measured.channels) == ["A1", "A2"] and lay_a.ids == ["A1", "A2"]
    assert sorted(b_a.simulated) == ["A1", "A2"]


def test_the_verdict_names_what_a_share_was_measured_against():
    """A named cause's share (significance.assess) is of the misfit above the noise, or — with J_ref within
    the noise margin or below the noise objective — of that margin, 0.5 J_noise; the verdict says which, so a
    report whose J_ref (0.038) is below J_noise (0.057) does not speak of "the misfit above the noise". The
    verdict reads which from the evidence (``share_of``), not by deciding the rule again."""
    limits = {"none_margin": 0.5}
    above = report._share({"share_of_explainable_misfit": 0.9, "share_of": "misfit_above_noise",
                           "objective_reference": 0.38, "objective_noise": 0.057, "thresholds": limits})
    below = report._share({"share_of_explainable_misfit": 0.64, "share_of": "noise_margin",
                           "objective_reference": 0.038, "objective_noise": 0.057, "thresholds": limits})
    assert above == "90 % of the misfit above the noise"
    assert below.startswith("64 % of the noise objective's margin") and "0.057" in below
    assert "undefined" in report._share({"share_of_explainable_misfit": None})
    # with the model's own time-step error in the floor (significance.floor_objective) the verdict names it
    step = report._share({"share_of_explainable_misfit": 0.33, "share_of": "misfit_above_noise",
                          "objective_reference": 0.19, "objective_noise": 0.067, "objective_floor": 0.11,
                          "thresholds": limits})
    assert step.startswith("33 % of the misfit above the noise and the model's own step error") and "0.11" in step
    margin = report._share({"share_of_explainable_misfit": 0.3, "share_of": "noise_margin",
                            "objective_reference": 0.12, "objective_noise": 0.067, "objective_floor": 0.11,
                            "thresholds": limits})
    assert "the model's step error" in margin and "0.11" in margin
