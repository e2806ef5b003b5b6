"""The run's figures with fixed margins (orchestrator.results.plots.set_margins): nothing clipped,
nothing drawn over another axes; the PNG writer's compression loses nothing.

The margins are constants in inches chosen for labels of a given width, so these tests draw each
figure with data whose tick labels are wider than the run's (6 characters, "-20000", and 8-character
sleeper/rail labels in the titles) and ask matplotlib's renderer (the independent reference here)
where every label landed.
"""
from __future__ import annotations

from types import SimpleNamespace

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.transforms import Bbox  # noqa: E402
from PIL import Image  # noqa: E402

from orchestrator.results import plots  # noqa: E402
from orchestrator.results.plots_layout import plot_layout  # noqa: E402
from track.layout import build_layout  # noqa: E402
from track.params import LayoutParams  # noqa: E402

# Extents are in pixels at the figure's 100 dpi and rounded by the renderer to whole pixels: a
# label may touch an edge to within one pixel, not cross it.
PX = 1.0


def _wide(n: int, lo: float, hi: float) -> np.ndarray:
    """A smooth signal from ``lo`` to ``hi`` and back (tick labels such as "-20000")."""
    s = np.linspace(0.0, 1.0, n)
    return lo + (hi - lo) * np.sin(np.pi * s) ** 2


def _body(coord):
    return SimpleNamespace(coord=coord, w=_wide(coord.size, -1.2e-3, 0.3e-3),
                           moment=_wide(coord.size, -2.0e7, 3.0e7))


def _figures():
    """Each figure of ``turnout run`` (and the FRF, contact-path and layout figures) on wide data."""
    t = np.linspace(0.0, 0.5, 5001)
    x = np.linspace(1000.0, 1010.0, 60)
    y = np.linspace(-1.3, 2.8, 30)
    series = {f"rail under wheel {i + 1}": _wide(t.size, -20000.0, 30000.0 + i) for i in range(4)}
    f = np.linspace(1.0, 2000.0, 400)
    H = 1e-9 / (1.0 - (f / 600.0) ** 2 + 0.1j * f / 600.0)
    nt = 400
    parts = np.column_stack([np.linspace(1, 0, nt), np.linspace(0, 1, nt)]) * 1e5
    eta = np.column_stack([np.linspace(0.03, 0.08, nt), np.linspace(0.01, 0.02, nt)])
    return {
        "moments": plots.plot_body_lines({"t = 0.2700 s (max rail moment)": _body(x)},
                                         {"t = 0.2700 s (max sleeper moment)": _body(y)},
                                         "crossing-1-12-through-120: instants of maximum moment",
                                         "crossing", "sleeper_21 (crossing transition)",
                                         marks_rail=[1005.0], marks_sleeper=[-0.75, 0.75]),
        "envelopes": plots.plot_envelopes(x, np.stack([_wide(60, -2e7, 0), _wide(60, 0, 3e7)]), y,
                                          np.stack([_wide(30, -2e7, 0), _wide(30, 0, 3e7)]), y,
                                          _wide(30, 0, 2.5e7), "crossing", "sleeper_21"),
        "time series": plots.plot_time_series(t, series, "vertical displacement [mm]",
                                              "crossing-1-12-through-120: wheel and rail displacement"),
        "frf": plots.plot_frf(f, {"rail at the nose": H, "sleeper": 2 * H}, "receptance at the nose"),
        "contact path": plots.plot_contact_path(np.linspace(36.0, 40.0, nt), eta, _wide(nt, -2.5e-3, 1e-3),
                                                parts, 37.0, "wheel 1"),
        "layout": plot_layout(build_layout(LayoutParams(type="turnout", crossing="1:12", radius=500.0))),
    }


@pytest.fixture(scope="module")
def figures():
    figs = _figures()
    for fig in figs.values():
        fig.draw_without_rendering()   # ticks, labels and legends at their final places
    yield figs
    for fig in figs.values():
        plt.close(fig)


def _inside(inner: Bbox, outer: Bbox) -> bool:
    return (inner.x0 >= outer.x0 - PX and inner.y0 >= outer.y0 - PX
            and inner.x1 <= outer.x1 + PX and inner.y1 <= outer.y1 + PX)


def _overlap(a: Bbox, b: Bbox) -> bool:
    """The two boxes share more than a pixel's width (touching edges do not count)."""
    return min(a.x1, b.x1) - max(a.x0, b.x0) > PX and min(a.y1, b.y1) - max(a.y0, b.y0) > PX


@pytest.mark.parametrize("name", ["moments", "envelopes", "time series", "frf", "contact path", "layout"])
def test_fixed_margins_clip_nothing_and_keep_labels_off_other_axes(figures, name):
    """Every axes with its tick labels, axis labels, title and legend lies on the canvas, clear of
    every other axes' plotting area; a suptitle lies on the canvas above every axes' decorations;
    a legend placed outside the axes hides none of the plotting area."""
    fig = figures[name]
    r = fig.canvas.get_renderer()
    tight = [ax.get_tightbbox(r) for ax in fig.axes]
    for i, (ax, box) in enumerate(zip(fig.axes, tight)):
        assert _inside(box, fig.bbox), (name, i, box.extents, fig.bbox.extents)
        for j, other in enumerate(fig.axes):
            if j != i:
                assert not _overlap(box, other.bbox), (name, i, j)
        leg = ax.get_legend()
        if leg is not None and leg.get_bbox_to_anchor().x0 >= ax.bbox.x1 - PX:   # placed outside
            assert not _overlap(leg.get_window_extent(r), ax.bbox), name
    if fig._suptitle is not None:
        sup = fig._suptitle.get_window_extent(r)
        assert _inside(sup, fig.bbox), name
        assert all(not _overlap(sup, box) for box in tight), name


def test_png_level_keeps_every_pixel_and_other_formats_still_write(tmp_path):
    """The PNG written at zlib level PNG_COMPRESS_LEVEL decodes to the same pixels as matplotlib's
    default PNG (zlib is lossless: any difference would be a bug in the options passed), and a
    suffix other than .png (whose writer takes no Pillow options) is written too."""
    def fig():
        f, ax = plt.subplots(figsize=(3, 2))
        ax.plot(np.arange(10.0), np.arange(10.0) ** 2)
        plots.set_margins(f)
        return f
    plots.save(fig(), tmp_path / "level.png")
    ref = fig()
    ref.savefig(tmp_path / "default.png", dpi=110)
    plt.close(ref)
    a = np.asarray(Image.open(tmp_path / "level.png"))
    b = np.asarray(Image.open(tmp_path / "default.png"))
    assert a.shape == b.shape and np.array_equal(a, b)
    for suffix in (".pdf", ".svg"):
        plots.save(fig(), tmp_path / f"figure{suffix}")
        assert (tmp_path / f"figure{suffix}").stat().st_size > 0
