"""Plots of track results (matplotlib imported inside each function; each returns a Figure)."""
from __future__ import annotations

import numpy as np

# A time series longer than this many points is drawn through the minimum and maximum of each of
# MAX_POINTS / 2 equal slices: with 5001 points at the 110 dpi of :func:`save` a 10-inch axes gives
# each pixel column 5-6 samples, whose vertical extent the slice's min and max already draw. It paid
# while the legend searched the "best" place, scanning every point (0.19 s -> 0.12 s); with the
# legend outside the axes (:func:`legend_outside`) both take 0.12 s (displacements.png, measured).
MAX_POINTS = 2000


def decimate(t: np.ndarray, y: np.ndarray, max_points: int = MAX_POINTS) -> tuple[np.ndarray, np.ndarray]:
    """The points of a line that show at plotting resolution: per slice its minimum and maximum.

    Parameters
    ----------
    t, y : ndarray, shape (n,)
        Abscissa (increasing) and values.
    max_points : int
        At most this many points are kept (even, >= 4); shorter series are returned as they are.

    Returns
    -------
    t, y : ndarray
        The first and last points and, for each of ``max_points // 2`` slices, its minimum and
        maximum in their order along ``t``. NaN values are kept out of the slices' extremes.
    """
    t, y = np.asarray(t), np.asarray(y, float)
    n = t.size
    if n <= max_points:
        return t, y
    k = max_points // 2
    width = -(-n // k)                                 # samples per slice (the last may be short)
    padded = np.full(k * width, np.nan)
    padded[:n] = y
    rows = padded.reshape(k, width)
    nan = np.isnan(rows)
    start = np.arange(k) * width
    lo = start + np.where(nan, np.inf, rows).argmin(axis=1)   # an all-NaN slice gives its first sample
    hi = start + np.where(nan, -np.inf, rows).argmax(axis=1)
    idx = np.unique(np.concatenate([[0, n - 1], np.minimum(lo, n - 1), np.minimum(hi, n - 1)]))
    return t[idx], y[idx]


# Fixed margins around the axes [in] in place of ``fig.tight_layout()``, which measured each axes'
# decorations and cost 0.15-0.2 s of a figure's 0.3-0.4 s. Text sizes are in points, so the room the
# labels need is constant in inches whatever the figure's size. LEFT: a y label and tick labels of up to
# 7 characters at 10 pt ("-1000.5"; tight_layout gave 0.57 in for "140", 0.73 in for "-1.25");
# BOTTOM: tick labels and an x label; TOP: a title; TOP_SUPTITLE: a title and a suptitle above it;
# RIGHT: the last tick label's overhang; GAP_X: a y label and tick labels between two columns;
# GAP_Y: space between two rows sharing x (no tick labels or titles between them).
LEFT, RIGHT, BOTTOM, TOP, TOP_SUPTITLE = 1.0, 0.25, 0.6, 0.4, 0.75
GAP_X, GAP_Y = 1.05, 0.25
LINE = 0.2          # one more line of a 10 pt label
LEGEND_PAD = 0.15   # between a legend outside the axes and the figure's right edge


def set_margins(fig, left: float = LEFT, right: float = RIGHT, bottom: float = BOTTOM, top: float = TOP,
                wspace: float = GAP_X, hspace: float = GAP_Y) -> None:
    """Place a figure's grid of axes by fixed margins and gaps in inches (``subplots_adjust``).

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        A figure whose axes are one grid (``plt.subplots``).
    left, right, bottom, top : float
        Space between the figure's edges and the grid [in].
    wspace, hspace : float
        Space between two columns / two rows of axes [in].
    """
    width, height = fig.get_size_inches()
    nrows, ncols = fig.axes[0].get_subplotspec().get_gridspec().get_geometry()
    ax_w = (width - left - right - (ncols - 1) * wspace) / ncols     # subplots_adjust's gaps are
    ax_h = (height - bottom - top - (nrows - 1) * hspace) / nrows    # fractions of an axes' size
    fig.subplots_adjust(left=left / width, right=1 - right / width, bottom=bottom / height,
                        top=1 - top / height, wspace=wspace / ax_w, hspace=hspace / ax_h)


def set_title(ax, text: str) -> None:
    """An axes' title at the fixed place above it (6 pt over the top spine).

    Given its height (``y=1.0``), a title is not moved up past what may stand above the axes (top
    tick labels, an offset text such as "1e-5"): looking for those measured every y tick label again,
    0.02 s an axes at each draw. None of these figures puts tick labels above an axes, and the y
    offset text stands at the axes' left edge, clear of a centred title.
    """
    ax.set_title(text, y=1.0)


def legend_outside(fig, legend) -> None:
    """Make room right of a one-column figure's axes for ``legend``, drawn there (``bbox_to_anchor``
    at the axes' upper right corner): no data hidden, and no search for the "best" place.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        A figure with one column of axes.
    legend : matplotlib.legend.Legend
        The legend, placed with ``loc="upper left", bbox_to_anchor=(1.0, 1.0)``.
    """
    width = legend.get_window_extent(fig.canvas.get_renderer()).width / fig.dpi
    set_margins(fig, right=width + LEGEND_PAD)


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def plot_body_lines(rail, sleeper, title: str, rail_label: str, sleeper_label: str,
                    marks_rail=(), marks_sleeper=()):
    """Deflection and bending moment along a rail and a sleeper (like seed 001 Figs. 4-5).

    Parameters
    ----------
    rail, sleeper : dict of label -> track.post.BodyResponse (one state each)
    marks_rail, marks_sleeper : sequence of float
        Positions to mark with dashed lines (e.g. wheels, TCP) [m].
    """
    plt = _plt()
    fig, ax = plt.subplots(2, 2, figsize=(11, 6.5), sharex="col")
    for col, (data, label, marks) in enumerate(((rail, rail_label, marks_rail),
                                                (sleeper, sleeper_label, marks_sleeper))):
        for name, br in data.items():
            ax[0, col].plot(br.coord, 1e3 * br.w, label=name)
            ax[1, col].plot(br.coord, 1e-3 * br.moment, label=name)
        for m in marks:
            ax[0, col].axvline(m, ls="--", c="0.5", lw=0.8)
            ax[1, col].axvline(m, ls="--", c="0.5", lw=0.8)
        set_title(ax[0, col], label)
        ax[0, col].set_ylabel("vertical displacement [mm]")
        ax[1, col].set_ylabel("bending moment [kN m]")
        ax[1, col].set_xlabel("track coordinate x [m]" if col == 0 else "lateral coordinate y [m]")
        ax[0, col].legend(fontsize=8)
        for a in ax[:, col]:
            a.grid(alpha=0.3)
    fig.suptitle(title)
    set_margins(fig, top=TOP_SUPTITLE)
    return fig


def plot_envelopes(coord_r, env_r, coord_s, env_s, y_p, p_max, rail_label, sleeper_label):
    """Min/max bending-moment envelopes of a rail and a sleeper, and peak ballast pressure."""
    plt = _plt()
    fig, ax = plt.subplots(1, 3, figsize=(14, 4))
    for a, c, e, lab in ((ax[0], coord_r, env_r, rail_label), (ax[1], coord_s, env_s, sleeper_label)):
        a.fill_between(c, 1e-3 * e[0], 1e-3 * e[1], alpha=0.4)
        a.plot(c, 1e-3 * e[1], lw=1)
        a.plot(c, 1e-3 * e[0], lw=1)
        set_title(a, f"moment envelope: {lab}")
        a.set_ylabel("bending moment [kN m]")
        a.grid(alpha=0.3)
    ax[0].set_xlabel("x [m]")
    ax[1].set_xlabel("y [m]")
    ax[2].plot(y_p, 1e-3 * p_max, "o-")
    set_title(ax[2], f"peak ballast pressure: {sleeper_label}")
    ax[2].set_xlabel("y [m]")
    ax[2].set_ylabel("pressure [kPa]")
    ax[2].grid(alpha=0.3)
    set_margins(fig)
    return fig


def plot_time_series(t, series: dict, ylabel: str, title: str):
    """Several signals against time (each :func:`decimate`-d to what shows)."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(10, 4))
    for name, y in series.items():
        ax.plot(*decimate(t, y), label=name, lw=1)
    ax.set_xlabel("time [s]")
    ax.set_ylabel(ylabel)
    set_title(ax, title)
    ax.grid(alpha=0.3)
    legend_outside(fig, ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.0, 1.0)))
    return fig


def plot_frf(f, H_by_label: dict, title: str):
    """Receptance magnitude (log) and phase."""
    plt = _plt()
    fig, ax = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    for lab, H in H_by_label.items():
        ax[0].semilogy(f, np.abs(H), label=lab)
        ax[1].plot(f, np.degrees(np.angle(H)), label=lab)
    ax[0].set_ylabel("receptance [m/N]")
    ax[1].set_ylabel("phase [deg]")
    ax[1].set_xlabel("frequency [Hz]")
    set_title(ax[0], title)
    ax[0].legend(fontsize=8)
    for a in ax:
        a.grid(alpha=0.3, which="both")
    set_margins(fig, hspace=GAP_Y)
    return fig


def plot_contact_path(x, eta, z, parts, x_tcp: float, label: str):
    """The contact point's path on the wing rail and the nose seen from above (lateral position on the
    rail section against x - x_tcp, one colour per surface, only where it carries force) and the
    wheel's vertical trajectory, for one wheel through the crossing (profile contact).

    Parameters
    ----------
    x : ndarray (nt,)     wheel track coordinate [m].
    eta : ndarray (nt, 2) lateral contact position on wing rail / nose [m] (NaN unloaded).
    z : ndarray (nt,)     wheel vertical position [m].
    parts : ndarray (nt, 2) force on wing rail / nose [N].
    """
    plt = _plt()
    fig, ax = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    d = x - x_tcp
    sel = (d > -0.5) & (d < 1.5)
    for k, name in enumerate(("wing rail", "nose")):
        on = sel & (parts[:, k] > 0)
        ax[0].plot(d[on], 1e3 * eta[on, k], ".", ms=2, label=name)
    ax[0].set_ylabel("contact position [mm] from the\nthrough route's running edge")
    set_title(ax[0], f"{label}: contact path through the crossing (top view) and wheel trajectory")
    ax[0].legend(fontsize=8)
    ax[1].plot(d[sel], 1e3 * z[sel], lw=1)
    ax[1].set_ylabel("wheel z [mm]")
    ax[1].set_xlabel("x - x_tcp [m]")
    for a in ax:
        a.grid(alpha=0.3)
    set_margins(fig, left=LEFT + LINE, hspace=GAP_Y)   # the upper y label has two lines
    return fig


# zlib level of the PNG files: 3 instead of Pillow's 6 encodes the run's figures in 17-25 ms instead of
# 27-41 ms each, for files 0-14 % larger (measured on the default run's five figures).
PNG_COMPRESS_LEVEL = 3


def save(fig, path) -> None:
    """Write a figure (PNG at 110 dpi, or the format of ``path``'s suffix) and release it."""
    _write(fig, path, png=str(path).lower().endswith(".png"))


def png_bytes(fig) -> bytes:
    """The PNG :func:`save` would write, as bytes (drawn in one process, written by another); releases the figure."""
    import io
    buf = io.BytesIO()
    _write(fig, buf, png=True, format="png")
    return buf.getvalue()


def _write(fig, target, png: bool, **kwargs) -> None:
    import matplotlib.pyplot as plt
    if png:   # only the PNG writer takes Pillow's options
        kwargs["pil_kwargs"] = {"compress_level": PNG_COMPRESS_LEVEL}
    fig.savefig(target, dpi=110, **kwargs)
    plt.close(fig)
