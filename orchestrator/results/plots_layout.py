"""Plan-view plot of a generated track layout (:func:`track.layout.build_layout`)."""
from __future__ import annotations

from orchestrator.results.plots import set_margins, set_title

# Colour per plan-line kind (PlanLine.kind).
KIND_COLOURS = {"stock": "black", "closure": "tab:blue", "rail": "dimgray", "wing": "tab:orange",
                "nose": "tab:red", "check": "tab:green"}
LABEL_EVERY = 5  # sleeper indices are written on every 5th sleeper


def plot_layout(layout, ax=None):
    """Plan view of ``layout``: rails by kind, sleepers, TCP and transition sleeper.

    Parameters
    ----------
    layout : track.layout.Layout
        The generated layout.
    ax : matplotlib.axes.Axes, optional
        Axes to draw into; a new figure is created when omitted.

    Returns
    -------
    matplotlib.figure.Figure
        The figure holding ``ax``. x [m] along the through route, y [m] lateral
        (the lateral scale is exaggerated; the aspect ratio is not equal).
    """
    import matplotlib.pyplot as plt

    if ax is None:
        fig, ax = plt.subplots(figsize=(14, 4.5))
        set_margins(fig)   # fixed margins (plots.LEFT ...) rather than matplotlib's default ones
    else:
        fig = ax.figure
    _draw_sleepers(ax, layout)
    _draw_rails(ax, layout)
    ax.set_xlabel("x along the through route [m]")
    ax.set_ylabel("y lateral [m] (+ left)")
    set_title(ax, _title(layout))
    ax.autoscale_view()
    ax.legend(loc="upper left", fontsize=7, ncol=4)
    return fig


def _draw_sleepers(ax, layout) -> None:
    """The sleepers into ``ax`` as rectangles, every ``LABEL_EVERY``-th numbered, the transition sleeper in gold."""
    from matplotlib.patches import Rectangle

    transition = None
    if layout.x_transition is not None:
        transition = min(layout.sleepers, key=lambda sl: abs(sl.x - layout.x_transition)).index
    for sl in layout.sleepers:
        w = sl.profile.base.width
        hot = sl.index == transition
        for a, b in sl.pieces:      # two sleepers where the tracks have separated (track.layout._bearer)
            ax.add_patch(Rectangle((sl.x - w / 2, a), w, b - a, facecolor="gold" if hot else "0.85",
                                   edgecolor="darkgoldenrod" if hot else "0.6", lw=0.6, zorder=1,
                                   label="transition sleeper" if hot else None))
        if sl.index % LABEL_EVERY == 0 or hot:
            ax.text(sl.x, sl.y_start - 0.08, str(sl.index), ha="center", va="top", fontsize=7)


def _draw_rails(ax, layout) -> None:
    """The plan lines by kind, the rail seats (bushing positions) as dots and the TCP into ``ax``."""
    seen = set()
    for ln in layout.lines:
        colour = KIND_COLOURS.get(ln.kind, "purple")
        ax.plot(ln.x, ln.y, color=colour, lw=1.2, zorder=3,
                label=None if ln.kind in seen else ln.kind)
        seen.add(ln.kind)

    for r in layout.rails:  # rail seats (bushing positions) as dots
        xs = [st.x for st in r.seats]
        ys = [st.y for st in r.seats]
        ax.plot(xs, ys, ".", ms=2.5, color=KIND_COLOURS.get(
            {"crossing": "nose", "check": "check"}.get(r.kind, "rail")), zorder=4)

    if layout.x_tcp is not None:
        p = layout.params
        y_tcp = (p.gauge / 2) * (1 if p.hand == "left" else -1)
        ax.plot([layout.x_tcp], [y_tcp], "x", color="red", ms=9, mew=2, zorder=5, label="TCP")


def _title(layout) -> str:
    """Track type (and for a turnout crossing, radius, hand, route), sleeper count and spacing."""
    p = layout.params
    title = f"{p.type}"
    if p.type == "turnout":
        title += f" {p.crossing} R{p.radius:g} {p.hand} hand, route {p.route}"
    return title + f", {len(layout.sleepers)} sleepers @ {p.sleeper_spacing:g} m"
