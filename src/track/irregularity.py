"""Rail irregularities and wheel out-of-roundness as geometric inputs of the wheel–rail contact.

Rail: a vertical irregularity ``z(x)`` [m] per rail, up +, added to the surface heights under the
wheel (``delta_k = z_k + z_irr + w - z_wheel`` in :mod:`track.contact`'s convention), either
measured (:class:`RailIrregularity` from a table) or generated (:func:`irregularity_from_psd`)
as a stationary Gaussian process with a given one-sided PSD ``G(f)`` [m^2 / (cycle/m) = m^3]
over spatial frequency ``f = 1 / wavelength`` [cycle/m], variance ``int G df``:

    z(x_k) = sum_j A_j cos(2 pi f_j x_k) + B_j sin(2 pi f_j x_k),  A_j, B_j ~ N(0, G(f_j) df),
    f_j = j df,  df = 1 / (N dx),

on an even grid of N samples (summed by the inverse real FFT; the realisation is periodic with
period ``N dx``, so generate at least the length to be run). Frequencies outside the band
``[f_min, f_max]`` get no power. Random amplitudes (not only random phases), so a realisation
is Gaussian and its periodogram scatters as the process's does; the seed makes it reproducible.

Wheel: out-of-roundness as the radius deviation ``dr(theta)`` [m] (negative: material missing)
over the wheel angle ``theta`` [rad] from a reference mark, with ``theta = x / r0`` for the rolling
wheel:

* :class:`WheelFlat`: a flat of length ``L`` and depth ``d``. ``shape="sharp"``: the chord of a new
  flat, ``dr(theta) = (r0 - d) / cos(theta) - r0`` for ``|theta| < theta0``, ``cos(theta0) =
  (r0 - d)/r0`` (``L = 2 r0 sin(theta0)``, the chord's sagitta ``d ~ L^2 / (8 r0)``); ``shape="rounded"``: the worn
  flat of Newton & Clark (J. Mech. Eng. Sci. 21, 1979), ``dr = -(d/2)(1 + cos(2 pi s / L))`` for
  ``|s| < L/2`` along the circumference ``s = r0 theta``.
* :class:`WheelPolygon`: ``dr = a cos(n theta + phase)`` (order n, amplitude a).

The radius deviation is the wheel's geometric input where the wheel's curvature stays convex
over the contact (rounded flats, polygons); for a sharp flat a rigid wheel pivots about the
flat's edges, and the contact input then differs from ``dr`` (not modelled here).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def psd_function(f_table, G_table):
    """A one-sided PSD from a table: log-log interpolation between points, 0 outside.

    Parameters
    ----------
    f_table : array_like
        Spatial frequencies [cycle/m], increasing, > 0.
    G_table : array_like
        PSD values [m^3], > 0.
    """
    lf = np.log(np.asarray(f_table, dtype=float))
    lg = np.log(np.asarray(G_table, dtype=float))

    def G(f):
        f = np.asarray(f, dtype=float)
        with np.errstate(divide="ignore"):
            lfx = np.log(np.where(f > 0, f, np.nan))
        out = np.exp(np.interp(lfx, lf, lg))
        return np.where((f >= np.exp(lf[0])) & (f <= np.exp(lf[-1])), out, 0.0)
    return G


def irregularity_from_psd(psd, n: int, dx: float, seed: int, f_min: float = 0.0,
                          f_max: float = np.inf) -> np.ndarray:
    """One realisation of a stationary Gaussian irregularity with one-sided PSD ``psd(f)``.

    Parameters
    ----------
    psd : callable
        ``G(f)`` [m^3] of spatial frequency [cycle/m] (array in, array out).
    n : int
        Number of samples (even; the realisation's period is ``n dx``).
    dx : float
        Sample spacing [m] (Nyquist ``1 / (2 dx)``).
    seed : int
        Seed of ``numpy.random.default_rng``.
    f_min, f_max : float
        Band [cycle/m] that carries power (the zero frequency never does).

    Returns
    -------
    ndarray (n,)
        ``z(x_k)`` [m] at ``x_k = k dx``.
    """
    if n < 4 or n % 2:
        raise ValueError(f"n: must be an even number >= 4, got {n!r}")
    if not dx > 0:
        raise ValueError(f"dx: must be positive, got {dx!r}")
    rng = np.random.default_rng(seed)
    df = 1.0 / (n * dx)
    f = np.arange(n // 2 + 1) * df
    G = np.asarray(psd(f), dtype=float)
    band = (f > 0) & (f >= f_min) & (f <= f_max) & (np.arange(f.size) < n // 2)   # no Nyquist term
    sd = np.sqrt(np.where(band, G * df, 0.0))
    A = rng.standard_normal(f.size) * sd
    B = rng.standard_normal(f.size) * sd
    # irfft(c) = (1/n) sum c_j e^{i 2 pi j k / n} (+ conjugates): c_j = n (A_j - i B_j) / 2
    return np.fft.irfft(0.5 * n * (A - 1j * B), n)


@dataclass(frozen=True)
class RailIrregularity:
    """A vertical rail irregularity given at stations (measured or generated).

    Attributes
    ----------
    x : ndarray
        Stations [m], increasing.
    z : ndarray
        Irregularity [m] (up +); linear interpolation between stations, 0 outside.
    """

    x: np.ndarray
    z: np.ndarray

    def at(self, x) -> np.ndarray:
        """``z`` [m] at ``x`` [m] (array in, array out)."""
        return np.interp(np.asarray(x, dtype=float), self.x, self.z, left=0.0, right=0.0)

    @classmethod
    def generated(cls, psd, x0: float, length: float, dx: float, seed: int, **band) -> "RailIrregularity":
        """A realisation of :func:`irregularity_from_psd` from ``x0`` over ``length`` [m]."""
        n = int(math.ceil(length / dx / 2.0)) * 2
        z = irregularity_from_psd(psd, n, dx, seed, **band)
        return cls(x=x0 + dx * np.arange(n), z=z)


@dataclass(frozen=True)
class WheelFlat:
    """A wheel flat (module docstring).

    Attributes
    ----------
    length : float
        Flat length L [m] (chord for the sharp flat, base length for the rounded one).
    depth : float, optional
        Depth d [m]; for the sharp flat it follows from L if not given (``r0 - sqrt(r0^2 - L^2/4)``).
    radius : float
        Nominal wheel radius r0 [m].
    shape : str
        ``"sharp"`` (new flat, chord) or ``"rounded"`` (worn, Newton & Clark).
    angle : float
        Wheel angle of the flat's centre [rad].
    """

    length: float
    depth: float | None = None
    radius: float = 0.46
    shape: str = "rounded"
    angle: float = 0.0

    def __post_init__(self):
        if self.shape not in ("sharp", "rounded"):
            raise ValueError(f"shape: must be 'sharp' or 'rounded', got {self.shape!r}")
        if not 0.0 < self.length < 2.0 * self.radius:
            raise ValueError(f"length: must be in (0, 2 radius), got {self.length!r}")
        if self.shape == "rounded" and (self.depth is None or not self.depth > 0):
            raise ValueError(f"depth: a rounded flat needs a positive depth, got {self.depth!r}")

    @property
    def flat_depth(self) -> float:
        """Depth d [m] (given, or the chord's for a sharp flat)."""
        if self.depth is not None:
            return float(self.depth)
        r, L = self.radius, self.length
        return r - math.sqrt(r * r - 0.25 * L * L)

    def radius_deviation(self, theta) -> np.ndarray:
        """``dr(theta)`` [m] at wheel angles ``theta`` [rad] (periodic in 2 pi)."""
        th = np.angle(np.exp(1j * (np.asarray(theta, dtype=float) - self.angle)))   # wrapped to (-pi, pi]
        r, d = self.radius, self.flat_depth
        if self.shape == "sharp":
            th0 = math.acos((r - d) / r)
            inside = np.abs(th) < th0
            return np.where(inside, (r - d) / np.cos(np.where(inside, th, 0.0)) - r, 0.0)
        s = r * th
        L = self.length
        return np.where(np.abs(s) < 0.5 * L, -0.5 * d * (1.0 + np.cos(2.0 * np.pi * s / L)), 0.0)

    def at(self, x) -> np.ndarray:
        """``dr`` [m] of the rolling wheel at track position ``x`` [m] (``theta = x / r0``)."""
        return self.radius_deviation(np.asarray(x, dtype=float) / self.radius)


@dataclass(frozen=True)
class WheelPolygon:
    """Polygonal wheel: ``dr = amplitude cos(order theta + phase)``.

    Attributes
    ----------
    order : int
        Number of harmonics around the wheel (n >= 1).
    amplitude : float
        Radius amplitude [m].
    phase : float
        [rad].
    radius : float
        Nominal wheel radius [m].
    """

    order: int
    amplitude: float
    phase: float = 0.0
    radius: float = 0.46

    def __post_init__(self):
        if not (isinstance(self.order, (int, np.integer)) and self.order >= 1):
            raise ValueError(f"order: must be an integer >= 1, got {self.order!r}")

    def radius_deviation(self, theta) -> np.ndarray:
        return self.amplitude * np.cos(self.order * np.asarray(theta, dtype=float) + self.phase)

    def at(self, x) -> np.ndarray:
        """``dr`` [m] at track position ``x`` [m]: wavelength ``2 pi r0 / order`` along the track."""
        return self.radius_deviation(np.asarray(x, dtype=float) / self.radius)


IRREGULARITY_DX = 0.005   # m, sample spacing of a generated rail irregularity (Nyquist: 1 cm wavelength)


@dataclass(frozen=True)
class Irregularities:
    """The irregularities of a scenario as one vertical input per wheel (:mod:`track.cosim`).

    ``r_i(x) = z_rail,side(i)(x) + dr_i(x)``: the rail irregularity under wheel i plus its radius
    deviation, both raising the contact (``delta_k = z_k + r_i + w - z_wheel``), so the track
    gives the wheel at ``z`` the force of the smooth geometry at ``z - r_i``.

    Attributes
    ----------
    rails : tuple of 2 (RailIrregularity or None)
        Left and right rail.
    wheels : tuple
        Per wheel a :class:`WheelFlat` / :class:`WheelPolygon` or None.
    """

    rails: tuple
    wheels: tuple

    def at(self, x: np.ndarray, sides: list) -> np.ndarray:
        """``r_i`` [m] of every wheel at its track coordinate ``x[i]`` (sides ``left``/``right``)."""
        out = np.zeros(len(sides))
        for i, (xi, side) in enumerate(zip(np.asarray(x, dtype=float).tolist(), sides)):
            rail = self.rails[0 if side == "left" else 1]
            if rail is not None:
                out[i] += float(rail.at(xi))
            w = self.wheels[i] if i < len(self.wheels) else None
            if w is not None:
                out[i] += float(w.at(xi))
        return out

    @classmethod
    def from_params(cls, contact, n_wheels: int, x0: float, length: float) -> "Irregularities | None":
        """From :class:`track.params.ContactParams` (None when it has none): a measured table
        ``(x, z_left, z_right)``, or a PSD realisation over ``[x0, x0 + length]`` (left: seed, right:
        seed + 1, band of wavelengths ``rail_psd_band``); a flat / polygon on the leading wheelset
        (wheels 1 and 2, the same angle)."""
        if not contact.irregular:
            return None
        rails = (None, None)
        if contact.rail_table:
            x, zl, zr = (np.asarray(v, dtype=float) for v in contact.rail_table)
            rails = (RailIrregularity(x, zl), RailIrregularity(x, zr))
        elif contact.rail_psd:
            psd = psd_function(*contact.rail_psd)
            lam_min, lam_max = contact.rail_psd_band
            band = dict(f_min=1.0 / lam_max, f_max=1.0 / lam_min)
            seed = int(contact.rail_psd_seed)
            rails = tuple(RailIrregularity.generated(psd, x0, length, IRREGULARITY_DX, seed + k, **band)
                          for k in (0, 1))
        wheel = None
        if contact.wheel_flat:
            wheel = WheelFlat(**dict(contact.wheel_flat))
        elif contact.wheel_polygon:
            wheel = WheelPolygon(**dict(contact.wheel_polygon))
        wheels = tuple(wheel if i < 2 else None for i in range(n_wheels))
        return cls(rails=rails, wheels=wheels)
