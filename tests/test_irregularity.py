"""Rail irregularity from a PSD and wheel out-of-roundness (:mod:`track.irregularity`)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import welch

from track.irregularity import (
    RailIrregularity,
    WheelFlat,
    WheelPolygon,
    irregularity_from_psd,
    psd_function,
)

G0, F0 = 1e-7, 0.5           # m^3, cycle/m: target G = G0 / (1 + (f/F0)^2)
F_LO, F_HI = 0.05, 8.0       # band that carries power [cycle/m]


def _target(f):
    f = np.asarray(f, dtype=float)
    return G0 / (1.0 + (f / F0) ** 2)


def test_generated_psd_reproduces_the_target():
    """48 realisations (seeds 0..47) of 16384 samples at 5 cm; their PSD by Welch's method (scipy,
    Hann, 4096-sample segments, 50 % overlap: an estimator independent of the generator), averaged
    over the realisations, against the target in 10 log-spaced bands between 0.15 and 4 cycle/m
    (inside the power band, away from its edges where the window's leakage blurs the cut).

    Tolerance 12 % per band: 48 x 7 segments give each Welch bin a relative standard error of
    about 1/sqrt(336 x 0.5) = 7.7 % (Hann overlap efficiency ~ 0.5); each band holds >= 12 bins of
    which about half are independent (the Hann main lobe spans 2 bins): <= 3.2 % per band; 12 %
    is 3.8 of those, plus the window's bias on the f^-2 slope (< 1 %: Hann leakage falls off as f^-6
    in power)."""
    dx, n, M = 0.05, 16384, 48
    est = None
    for seed in range(M):
        z = irregularity_from_psd(_target, n, dx, seed, f_min=F_LO, f_max=F_HI)
        f, P = welch(z, fs=1.0 / dx, window="hann", nperseg=4096, noverlap=2048, detrend=False)
        est = P if est is None else est + P
    est /= M
    edges = np.geomspace(0.15, 4.0, 11)
    for a, b in zip(edges[:-1], edges[1:]):
        m = (f >= a) & (f < b)
        assert m.sum() >= 12
        ratio = est[m].mean() / _target(f[m]).mean()
        assert ratio == pytest.approx(1.0, abs=0.12), (a, b, ratio)


def test_variance_is_the_integral_of_the_psd():
    """The variance of the process is int G df over the band (by hand: G0 F0 [atan(f/F0)] between
    the band edges). Averaged over 64 realisations of 4096 samples: the sample variance of one
    realisation scatters by ~ sqrt(2 / n_eff) with n_eff ~ the number of independent frequency
    components that carry the variance (about 60 below 2 F0 here): 18 %; over 64 realisations
    2.3 %; tolerance 8 %. The discrete sum over the FFT grid differs from the integral by < 1 %
    (grid step 1/205 cycle/m against the PSD's scale F0)."""
    dx, n, M = 0.05, 4096, 64
    var = np.mean([irregularity_from_psd(_target, n, dx, s, f_min=F_LO, f_max=F_HI).var() for s in range(M)])
    expect = G0 * F0 * (math.atan(F_HI / F0) - math.atan(F_LO / F0))
    assert var == pytest.approx(expect, rel=0.08)


def test_seed_and_band():
    """Same seed, same realisation; another seed, another; nothing outside the band (the FFT of the
    realisation has no power there, to round-off)."""
    a = irregularity_from_psd(_target, 1024, 0.05, 7, f_min=F_LO, f_max=2.0)
    np.testing.assert_array_equal(a, irregularity_from_psd(_target, 1024, 0.05, 7, f_min=F_LO, f_max=2.0))
    assert not np.allclose(a, irregularity_from_psd(_target, 1024, 0.05, 8, f_min=F_LO, f_max=2.0))
    spec = np.abs(np.fft.rfft(a)) ** 2
    f = np.fft.rfftfreq(1024, 0.05)
    assert spec[(f > 2.0) | (f < F_LO)].max() < 1e-20 * spec.max()
    with pytest.raises(ValueError, match="n:"):
        irregularity_from_psd(_target, 1023, 0.05, 0)


def test_psd_table_log_log():
    """A PSD table is interpolated log-log: a power law through two points is reproduced between
    them (round-off), 0 outside."""
    G = psd_function([0.1, 10.0], [1e-5, 1e-9])           # G = 1e-7 f^-2
    np.testing.assert_allclose(G([0.5, 1.0, 3.0]), 1e-7 * np.array([0.5, 1.0, 3.0]) ** -2, rtol=1e-12)
    assert G(20.0) == 0.0 and G(0.0) == 0.0


def test_rail_irregularity_table():
    r = RailIrregularity(x=np.array([0.0, 1.0, 2.0]), z=np.array([0.0, 1e-3, -1e-3]))
    np.testing.assert_allclose(r.at([0.5, 1.5, 3.0, -1.0]), [0.5e-3, 0.0, 0.0, 0.0], atol=1e-18)
    g = RailIrregularity.generated(_target, 10.0, 5.0, 0.01, seed=3, f_min=F_LO, f_max=F_HI)
    assert g.x[0] == 10.0 and g.x.size == 500


# ------------------------------------------------------------------ wheel out-of-roundness
def test_sharp_flat_is_the_chord():
    """New flat of length L = 50 mm on r0 = 0.46 m: the chord's sagitta r0 - sqrt(r0^2 - L^2/4) =
    0.6797 mm, ~ L^2 / (8 r0) = 0.6793 mm (relative difference (L / 2 r0)^2 / 4 ~ 7e-4). The radius
    deviation is -d at the centre, 0 at the chord's ends (theta0 = asin(L / 2 r0)) and beyond, and the
    contact line is straight: (r0 + dr) cos(theta) = r0 - d."""
    r, L = 0.46, 0.05
    fl = WheelFlat(length=L, radius=r, shape="sharp")
    d = fl.flat_depth
    assert d == pytest.approx(r - math.sqrt(r * r - L * L / 4), rel=1e-14)
    assert d == pytest.approx(L * L / (8 * r), rel=1e-3)
    th0 = math.asin(L / (2 * r))
    th = np.linspace(-0.99 * th0, 0.99 * th0, 41)
    np.testing.assert_allclose((r + fl.radius_deviation(th)) * np.cos(th), r - d, rtol=1e-14)
    assert float(fl.radius_deviation(0.0)) == pytest.approx(-d, rel=1e-14)
    assert float(fl.radius_deviation(1.01 * th0)) == 0.0
    assert float(fl.radius_deviation(2 * math.pi)) == pytest.approx(-d, rel=1e-12)   # periodic


def test_rounded_flat_newton_clark():
    """Rounded flat (Newton & Clark 1979): -(d/2)(1 + cos(2 pi s / L)): -d at the centre, -d/2 at
    s = L/4, 0 with zero slope at s = L/2 (C1); along the track x = r0 theta."""
    r, L, d = 0.46, 0.1, 1e-3
    fl = WheelFlat(length=L, depth=d, radius=r)
    s = np.array([0.0, L / 4, -L / 4, L / 2, 0.6 * L])
    np.testing.assert_allclose(fl.radius_deviation(s / r), [-d, -d / 2, -d / 2, 0.0, 0.0], atol=1e-18)
    # C1 at the edge: the slope there vanishes like 2 pi^2 d e / L^2 (4e-6 at e = 1 um), against the
    # largest slope pi d / L = 0.031 in the middle: bound 1e-3 of it
    e = 1e-6
    slope = (fl.at(L / 2 - e) - fl.at(L / 2 - 2 * e)) / e
    assert abs(float(slope)) < 1e-3 * math.pi * d / L
    with pytest.raises(ValueError, match="depth"):
        WheelFlat(length=L)


def test_polygon():
    """Order-n polygon: amplitude a, wavelength along the track 2 pi r0 / n."""
    p = WheelPolygon(order=8, amplitude=50e-6, radius=0.46)
    lam = 2 * math.pi * 0.46 / 8
    x = np.linspace(0.0, 1.0, 101)
    np.testing.assert_allclose(p.at(x + lam), p.at(x), atol=1e-18)
    assert float(p.at(0.0)) == pytest.approx(50e-6) and float(p.at(lam / 2)) == pytest.approx(-50e-6)
    with pytest.raises(ValueError, match="order"):
        WheelPolygon(order=0, amplitude=1e-5)
