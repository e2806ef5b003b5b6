"""Plots of track results (matplotlib imported inside each function; each returns a Figure)."""
from __future__ import annotations

import numpy as np

# A time series longer than this many points is drawn through the minimum and maximum of each of
# MAX_POINTS / 2 equal slices: with 5001 points at the 110 dpi of :func:`save` a 10-inch axes gives
# each pixel column 5-6 samples, whose vertical extent the slice's min and max already draw; the
# legend's "best" placement, which scans every point, costs 40 % less (measured 0.19 s -> 0.12 s).
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
        ax[0, col].set_title(label)
        ax[0, col].set_ylabel("vertical displacement [mm]")
        ax[1, col].set_ylabel("bending moment [kN m]")
        ax[1, col].set_xlabel("track coordinate x [m]" if col == 0 else "lateral coordinate y [m]")
        ax[0, col].legend(fontsize=8)
        for a in ax[:, col]:
            a.grid(alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def plot_envelopes(coord_r, env_r, coord_s, env_s, y_p, p_max, rail_label, sleeper_label):
    """Min/max bending-moment envelopes of a rail and a sleeper, and peak ballast pressure."""
    plt = _plt()
    fig, ax = plt.subplots(1, 3, figsize=(14, 4))
    for a, c, e, lab in ((ax[0], coord_r, env_r, rail_label), (ax[1], coord_s, env_s, sleeper_label)):
        a.fill_between(c, 1e-3 * e[0], 1e-3 * e[1], alpha=0.4)
        a.plot(c, 1e-3 * e[1], lw=1)
        a.plot(c, 1e-3 * e[0], lw=1)
        a.set_title(f"moment envelope: {lab}")
        a.set_ylabel("bending moment [kN m]")
        a.grid(alpha=0.3)
    ax[0].set_xlabel("x [m]")
    ax[1].set_xlabel("y [m]")
    ax[2].plot(y_p, 1e-3 * p_max, "o-")
    ax[2].set_title(f"peak ballast pressure: {sleeper_label}")
    ax[2].set_xlabel("y [m]")
    ax[2].set_ylabel("pressure [kPa]")
    ax[2].grid(alpha=0.3)
    fig.tight_layout()
    return fig


def plot_time_series(t, series: dict, ylabel: str, title: str):
    """Several signals against time (each :func:`decimate`-d to what shows)."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(10, 4))
    for name, y in series.items():
        ax.plot(*decimate(t, y), label=name, lw=1)
    ax.set_xlabel("time [s]")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
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
    ax[0].set_title(title)
    ax[0].legend(fontsize=8)
    for a in ax:
        a.grid(alpha=0.3, which="both")
    fig.tight_layout()
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
    ax[0].set_title(f"{label}: contact path through the crossing (top view) and wheel trajectory")
    ax[0].legend(fontsize=8)
    ax[1].plot(d[sel], 1e3 * z[sel], lw=1)
    ax[1].set_ylabel("wheel z [mm]")
    ax[1].set_xlabel("x - x_tcp [m]")
    for a in ax:
        a.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def save(fig, path) -> None:
    """Write a figure and release it."""
    import matplotlib.pyplot as plt
    fig.savefig(path, dpi=110)
    plt.close(fig)
