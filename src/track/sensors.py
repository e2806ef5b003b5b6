"""Virtual sensors: what a measuring campaign's transducers would read from the track model.

A sensor is a linear map of the track state, except the ballast pressure cell, which
reads the (bi-linear) bushing forces:

================  ============================================================  ========
type              reading                                                       unit
================  ============================================================  ========
``pressure``      sleeper-ballast contact pressure at ``coord`` on a sleeper,   Pa
                  linear between the two nearest ballast bushings
``acceleration``  vertical acceleration at ``coord`` on a body (on the solid    m/s^2
                  crossing rail: at the surface point ``z`` above the rail's
                  neutral axis, :data:`SOLID_DATUM`; ``z = 0``: on the web,
                  clear of the wheel's local deformation)
``displacement``  vertical displacement at ``coord`` on a body *reconstructed  m
                  from its accelerometer*, as the field team does it: the
                  simulated acceleration there goes through the very same
                  double integration with high-pass
                  (:func:`displacement_from_acceleration`) as the measured one
                  (a high-pass of the simulated displacement would not do: the
                  sleeper's displacement trend over a record is not in its
                  acceleration, and differs by up to 20 % of the signal);
                  on the solid at the accelerometer's surface point as above
``strain``        engineering longitudinal strain of a gauge of length          -
                  ``gauge_length`` centred at ``coord``, at height ``z`` above
                  the body's neutral axis (on the solid: the rail's,
                  :data:`SOLID_DATUM`): beams from the section rotations at
                  the gauge ends (:func:`track.post.strain_row`), the solid
                  crossing rail from the axial displacements of two surface
                  points at one height (:func:`solid_strain_row`); seed 000
                  eq. 1 with its typo fixed: strain = u / L;
                  on the solid that is the exact mean along the gauge of the
                  tetrahedra's eps_xx, and their eps_xx at the gauge centre
                  when the gauge lies in one element)
================  ============================================================  ========

Signs: displacement and acceleration up +, pressure compressive +, strain tensile +.

Every type works on both track models (``track.model: beam | solid``): sleepers are
beams either way; on the solid crossing rail a sensor reads the solid's recovered field
``u = T q`` at a point of its surface (the rows are ``T``'s rows interpolated with the
quadratic tetrahedra's shape functions there), so it stays a fixed row on ``q``.

:func:`compile_sensors` turns a list of :class:`Sensor` into row vectors on the model's
generalized coordinates once; :func:`sensor_signals` then reads whole histories with a
few matrix products (no Python loop over time steps).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .model import TrackModel
from .post import strain_row

SENSOR_TYPES = ("pressure", "displacement", "acceleration", "strain")
GAUGE_LENGTH = 0.1   # m: default strain-gauge base (a 100 mm gauge; also the beam element length)
RECONSTRUCTION_HIGHPASS = 5.0   # Hz: default corner of the displacement reconstruction filter
RECONSTRUCTION_ORDER = 2        # Butterworth order (applied forward and backward: zero phase)
ANTI_ALIAS_SHARE = 0.4          # anti-alias low-pass corner / sampling rate (anti_alias)
ANTI_ALIAS_ORDER = 4            # Butterworth order (applied forward and backward: zero phase, |H|^2)
# Sensors on the solid crossing rail: z is a height above the neutral axis of the untrimmed rail
# section, a place on the rail as a field layout gives it (track.solid.crossing.SolidCrossing.gauge_points).
# Ahead of the nose tip and along it the trimmed head lowers the solid's own neutral axis (52 mm instead
# of 81.5 mm above the foot ahead of the tip): a foot gauge stays on the foot and reads the solid's
# strain there, not a lever arm that would put it below the foot.
SOLID_DATUM = "rail"


@dataclass(frozen=True)
class Sensor:
    """One transducer.

    Attributes
    ----------
    id : str
        Channel name (the column in sensor CSVs).
    type : str
        One of :data:`SENSOR_TYPES`.
    group : str
        Sensor group (A-F as in seed 000 Fig. 2); objective weights are per group.
    body : str
        Body name in the track model (``sleeper_21``, ``crossing``, ...).
    coord : float
        Track coordinate on the body: x for rails, y for sleepers [m].
    z : float
        Height above the body's neutral axis [m] (up +): of a strain gauge; of an
        accelerometer on the solid crossing rail (beams: no part). On the solid the
        datum is the untrimmed rail section's neutral axis (:data:`SOLID_DATUM`).
    gauge_length : float
        Strain gauges: base length [m].
    """

    id: str
    type: str
    group: str
    body: str
    coord: float
    z: float = 0.0
    gauge_length: float = GAUGE_LENGTH


def sleeper_of(body: str) -> int | None:
    """The index of the sleeper a body name ``sleeper_<index>`` (as :mod:`track.model` names them) is; None
    for any other body (a rail, the solid crossing)."""
    return int(body.split("_")[1]) if body.startswith("sleeper_") else None


def sleepers_of(sensors) -> list[int]:
    """The indices of the sleepers carrying any of ``sensors`` (:func:`sleeper_of` of their bodies), sorted."""
    return sorted({k for k in (sleeper_of(s.body) for s in sensors) if k is not None})


@dataclass
class CompiledSensors:
    """Sensor rows on the generalized coordinates (see :func:`compile_sensors`).

    Attributes
    ----------
    sensors : tuple of Sensor
    Cq : ndarray, shape (ns, n)
        Rows of the sensors that read displacements q (strain); zero rows else.
    Ca : ndarray, shape (ns, n)
        Rows of the sensors that read accelerations (acceleration, displacement).
    Pb : ndarray, shape (ns, nb)
        Weights of the pressure sensors on the ballast bushings' pressures.
    """

    sensors: tuple
    Cq: np.ndarray
    Ca: np.ndarray
    Pb: np.ndarray

    @property
    def ids(self) -> list[str]:
        return [s.id for s in self.sensors]


def displacement_row(model: TrackModel, body: str, coord: float, z: float = 0.0) -> np.ndarray:
    """Vertical displacement at ``coord`` on ``body`` as a row on q, shape (n,).

    Beams: the deflection of the beam axis (``z`` plays no part: the section is rigid).
    The solid crossing rail: ``u_z`` of its surface point ``z`` [m] above the rail's neutral
    axis at ``coord`` (:data:`SOLID_DATUM`, :meth:`track.solid.crossing.SolidCrossing.vertical_rows`).
    """
    b = model.body(body)
    row = np.zeros(model.n)
    if b.solid:
        row[b.gdofs] = b.fom.vertical_rows(np.array([b.local(coord)]), z, datum=SOLID_DATUM)[0]
        return row
    pm = model.point(body, coord)
    row[pm.gidx] = pm.weights
    return row


def solid_strain_row(model: TrackModel, body: str, coord: float, z: float,
                     gauge_length: float = GAUGE_LENGTH) -> np.ndarray:
    """A strain gauge on the solid crossing rail as a row on q, shape (n,).

    Seed 000 eq. 1 (strain = u / L) between the gauge ends on the solid's surface, ``z`` [m]
    above the rail's neutral axis (:data:`SOLID_DATUM`): ``(u_x(c + L/2) - u_x(c - L/2)) / L``,
    the exact mean along the gauge of the quadratic tetrahedra's ``eps_xx``
    (:meth:`track.solid.crossing.SolidCrossing.gauge_row`).

    Raises
    ------
    ValueError
        The gauge is not on the solid, or its height is outside the rail section.
    """
    b = model.body(body)
    L = float(gauge_length)
    if not L > 0.0:
        raise ValueError(f"gauge_length: must be > 0, got {gauge_length!r}")
    ends = np.array([coord - 0.5 * L, coord + 0.5 * L])
    s0, s1 = b.origin + b.fom.contact_s[[0, -1]]
    if ends[0] < s0 - 1e-9 or ends[1] > s1 + 1e-9:
        raise ValueError(f"gauge {ends[0]:.3f}..{ends[1]:.3f} m is not on {body} ({s0:.3f}..{s1:.3f} m)")
    row = np.zeros(model.n)
    row[b.gdofs] = b.fom.gauge_row(b.local(coord), z, L, datum=SOLID_DATUM)
    return row


def pressure_weights(model: TrackModel, sleeper: int, y: float) -> np.ndarray:
    """Weights on all bushing pressures for a pressure cell at lateral position ``y``, shape (nb,)."""
    bal = model.ballast
    idx = np.flatnonzero(bal.sleeper == sleeper)
    if idx.size == 0:
        raise ValueError(f"sleeper {sleeper} has no ballast bushings")
    ys = bal.y[idx]
    order = np.argsort(ys)
    idx, ys = idx[order], ys[order]
    w = np.zeros(bal.y.size)
    if y <= ys[0] or idx.size == 1:
        w[idx[0]] = 1.0
    elif y >= ys[-1]:
        w[idx[-1]] = 1.0
    else:
        j = int(np.searchsorted(ys, y)) - 1
        xi = (y - ys[j]) / (ys[j + 1] - ys[j])
        w[idx[j]], w[idx[j + 1]] = 1.0 - xi, xi
    return w


def compile_sensors(model: TrackModel, sensors) -> CompiledSensors:
    """Rows of every sensor on the model's coordinates.

    Raises
    ------
    ValueError
        An unknown type, body, a pressure cell on a body that is not a sleeper, or a
        sensor off its body (a gauge past the body's end, a height outside the solid
        rail's section).
    """
    sensors = tuple(sensors)
    ns = len(sensors)
    Cq, Ca = np.zeros((ns, model.n)), np.zeros((ns, model.n))
    Pb = np.zeros((ns, model.ballast.y.size))
    for i, s in enumerate(sensors):
        try:
            b = model.body(s.body)
        except KeyError:
            raise ValueError(f"sensor {s.id}: the track model has no body {s.body!r}") from None
        gap = model.layout.sleepers[b.sleeper].gap if b.sleeper >= 0 else ()
        if gap and gap[0] < s.coord < gap[1]:
            raise ValueError(f"sensor {s.id}: y = {s.coord:.3f} m is between the two sleepers of position "
                             f"{b.sleeper} ({gap[0]:.3f}..{gap[1]:.3f} m, one under each track): no sleeper there")
        if s.type == "pressure":
            if b.sleeper < 0:
                raise ValueError(f"sensor {s.id}: a pressure cell must be under a sleeper, not on {s.body!r}")
            Pb[i] = pressure_weights(model, b.sleeper, s.coord)
        elif s.type in ("displacement", "acceleration"):   # both read an accelerometer
            Ca[i] = displacement_row(model, s.body, s.coord, s.z)
        elif s.type == "strain":
            row_of = solid_strain_row if b.solid else strain_row
            Cq[i] = row_of(model, s.body, s.coord, s.z, s.gauge_length)
        else:
            raise ValueError(f"sensor {s.id}: unknown type {s.type!r} (one of {', '.join(SENSOR_TYPES)})")
    return CompiledSensors(sensors, Cq, Ca, Pb)


def sensor_signals(model: TrackModel, compiled: CompiledSensors, q: np.ndarray, v: np.ndarray,
                   a: np.ndarray, dt: float, highpass: float = RECONSTRUCTION_HIGHPASS,
                   reconstruct: bool = True, columns: dict | None = None) -> dict[str, np.ndarray]:
    """Simulated sensor signals from state histories.

    Parameters
    ----------
    model : TrackModel
    compiled : CompiledSensors
    q, v, a : ndarray, shape (nt, n)
        Displacements [m], velocities [m/s], accelerations [m/s^2] at uniform times.
    dt : float
        Time step of the histories [s] (for the displacement reconstruction filter).
    highpass : float
        Corner [Hz] of the displacement reconstruction (:func:`displacement_from_acceleration`).
    reconstruct : bool
        ``False``: displacement sensors give their accelerometer's signal [m/s^2], to be
        reconstructed later on another time base (as the comparison with a measurement
        does, on the measured window).
    columns : dict, optional
        ``{"q": cols, "v": cols, "a": cols}``: ``q``, ``v``, ``a`` hold only these sorted
        columns of the states (a record of some columns, ``track.cosim.Record``), shape
        (nt, len(cols)); the states outside them count as zero, as in the full-width rows
        of ``track.cosim.state_rows``, without building those rows.

    Returns
    -------
    dict
        Sensor id -> signal, shape (nt,), SI units.
    """
    q, v, a = (np.atleast_2d(np.asarray(x, float)) for x in (q, v, a))
    D = model.ballast.dof
    if columns is None:
        out_q, out_a = q @ compiled.Cq.T, a @ compiled.Ca.T
        p = model.ballast.pressure(q[:, D], v[:, D]) @ compiled.Pb.T
    else:   # and only the bushings under pressure cells (the others' weights are 0)
        out_q, out_a = q @ compiled.Cq[:, columns["q"]].T, a @ compiled.Ca[:, columns["a"]].T
        cells = np.flatnonzero(np.any(compiled.Pb != 0.0, axis=0))
        p = model.ballast.subset(cells).pressure(_columns_of(q, columns["q"], D[cells]),
                                                 _columns_of(v, columns["v"], D[cells])) @ compiled.Pb[:, cells].T
    signals = {}
    for i, s in enumerate(compiled.sensors):
        if s.type == "pressure":
            signals[s.id] = p[:, i]
        elif s.type == "acceleration" or (s.type == "displacement" and not reconstruct):
            signals[s.id] = out_a[:, i]
        elif s.type == "displacement":
            signals[s.id] = displacement_from_acceleration(out_a[:, i], dt, highpass)
        else:
            signals[s.id] = out_q[:, i]
    return signals


def _columns_of(x: np.ndarray, cols: np.ndarray, dofs: np.ndarray) -> np.ndarray:
    """Columns ``dofs`` of states ``x`` that hold the sorted columns ``cols`` only: (nt, len(dofs)),
    zero for a dof that is not among them."""
    cols = np.asarray(cols)
    pos = np.minimum(np.searchsorted(cols, dofs), max(cols.size - 1, 0))
    have = cols[pos] == dofs if cols.size else np.zeros(dofs.size, bool)
    out = np.zeros((x.shape[0], dofs.size))
    out[:, have] = x[:, pos[have]]
    return out


# ----------------------------------------------------------------------------------------
# Displacement from acceleration: one filter for the measured and the simulated signal
# ----------------------------------------------------------------------------------------
def _highpass_gain(n: int, dt: float, f_c: float, order: int) -> tuple[np.ndarray, np.ndarray]:
    """Frequencies [Hz] of an rfft of length n and the zero-phase high-pass gain |H|^2 there."""
    f = np.fft.rfftfreq(n, dt)
    with np.errstate(divide="ignore"):
        r = np.where(f > 0, (f_c / np.where(f > 0, f, 1.0)) ** (2 * order), np.inf)
    return f, 1.0 / (1.0 + r)   # |H_butterworth|^2: the filter run forward and backward


def displacement_from_acceleration(acc: np.ndarray, dt: float, f_c: float = RECONSTRUCTION_HIGHPASS,
                                   order: int = RECONSTRUCTION_ORDER) -> np.ndarray:
    """Displacement reconstructed from an acceleration record (what a field team does).

    Double integration in the frequency domain, X = -A / (2 pi f)^2, with the same
    zero-phase Butterworth high-pass (|H|^2: forward and backward), which removes the
    integration's unbounded low-frequency gain. For an acceleration that is the second derivative
    of a displacement w it is w without its mean, its linear trend over the record
    (not in the acceleration) and its content well below ``f_c``.

    Parameters
    ----------
    acc : ndarray, shape (nt,)
        [m/s^2] at uniform times.
    dt : float
        [s].
    f_c : float
        Corner frequency [Hz] of the high-pass.
    order : int
        Butterworth order.

    Returns
    -------
    ndarray, shape (nt,)
        [m].
    """
    acc = np.asarray(acc, float)
    n = acc.shape[0]
    f, g = _highpass_gain(n, dt, f_c, order)
    A = np.fft.rfft(acc - acc.mean())
    with np.errstate(divide="ignore", invalid="ignore"):
        X = np.where(f > 0, -A / (2.0 * np.pi * np.where(f > 0, f, 1.0)) ** 2, 0.0) * g
    return np.fft.irfft(X, n=n)


def anti_alias(t: np.ndarray, x: np.ndarray, rate: float, share: float = ANTI_ALIAS_SHARE,
               order: int = ANTI_ALIAS_ORDER) -> np.ndarray:
    """Signals band-limited as an acquisition sampling at ``rate`` does before it samples.

    A data acquisition low-passes every channel below its Nyquist frequency before the converter
    samples it; content above it would fold into the band. Here: a Butterworth low-pass of corner
    ``share x rate`` (0.4: a sigma-delta converter's pass band ends at ~0.45 of its rate, an analogue
    anti-alias filter's corner sits lower), applied forward and backward (zero phase: a linear-phase
    digital filter whose delay the converter removes; the magnitude is |H|^2, -6 dB at the corner).
    Applied on the simulation's own output grid ``t`` (uniform), before any interpolation to the
    acquisition's times.

    Why (benchmarks/RESULTS.md, session 32): the model's rail accelerations and reconstructed sleeper
    displacements above ~1 kHz depend on its time step and hardly converge as it is halved (the
    measurement scenario at 2e-4 s against itself at 1e-4 s, 1e-4 against 5e-5, 5e-5 against 2.5e-5:
    objective J 0.076, 0.072, 0.053 on field-like null_clean 7000, whose noise is J 0.067); through this
    filter at 0.4 x 2.5 kHz they converge at about first order (0.034, 0.021, 0.011). A comparison of
    unfiltered model output with a record sampled at 2.5 kHz counts that step-dependent, folded content
    as misfit.

    Parameters
    ----------
    t : ndarray, shape (nt,)
        Uniform times [s] of the signals.
    x : ndarray, shape (nt,) or (nt, n)
        Signals (columns).
    rate : float
        The acquisition's sampling rate [Hz].

    Returns
    -------
    ndarray, like ``x``. Unchanged when the corner lies at or above the signals' own Nyquist frequency
    or the record is too short to filter.
    """
    from scipy.signal import butter, sosfiltfilt

    x = np.asarray(x, float)
    fs = 1.0 / float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    corner = share * float(rate)
    if not 0.0 < corner < 0.5 * fs:
        return x
    sos = butter(order, corner, fs=fs, output="sos")
    pad = 3 * (2 * len(sos) + 1)   # odd-extension length: sosfiltfilt's default for full second-order sections
    if x.shape[0] <= pad:
        return x
    return sosfiltfilt(sos, x, axis=0, padlen=pad)


__all__ = ["Sensor", "sleeper_of", "sleepers_of", "anti_alias", "ANTI_ALIAS_SHARE", "ANTI_ALIAS_ORDER", "SENSOR_TYPES", "CompiledSensors",
           "compile_sensors", "sensor_signals", "displacement_row", "solid_strain_row", "SOLID_DATUM", "pressure_weights", "displacement_from_acceleration"]
