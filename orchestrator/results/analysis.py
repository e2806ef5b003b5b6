"""Post-processing of one co-simulation with the same track model: the quantities of the seeds.

:func:`analyse` turns a :class:`orchestrator.cosim.master.CosimResult` into
- scalars: peak / minimum contact forces, ΔQ = Q_max - Q0 on the crossing side, the
  maximum bending moment along the crossing rail and along the sleeper under the
  crossing transition (with their instants), the peak sleeper-ballast pressure under
  that sleeper, on the crossing side and on the field side (seed 001 Fig. 6);
- arrays: the deflection and moment lines at those instants (seed 001 Figs. 4, 5, 7),
  the pressure along the sleeper at the instant of maximum sleeper moment (Fig. 6), the
  moment envelopes and the wheels' lateral positions on the sleeper.

The crossing side is the side whose wheel passes the nose; the *field side* of the
transition sleeper is the region around the other wheel's rail seat.

All of it reads few columns of the track states (:func:`analysis_columns`: the crossing
rail's and the transition sleeper's coordinates, the ballast nodes under that sleeper), so
the run records only those; the record is expanded to full rows a block at a time.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from track.cosim import state_rows
from track.model import TrackModel, reference_point
from track.post import BodyResponse, body_response, body_response_history, sleeper_pressure

SIDE_WINDOW = 0.3   # m: half-width of the sleeper region under a rail seat for the side pressures
STATE_BLOCK = 128   # output steps per block of full-width states (bounds the temporaries: 1.8 MB each for 1741
                    # dofs; 500 made the run's peak memory about 35 MB higher)


@dataclass
class Analysis:
    """Scalars (JSON-able floats) and arrays of one run (see module docstring)."""

    scalars: dict = field(default_factory=dict)
    arrays: dict = field(default_factory=dict)


def wheel_sides(m: int) -> list[str]:
    """Side of each wheel (1, 3, ... left)."""
    return ["left" if i % 2 == 0 else "right" for i in range(m)]


def seat_y(model: TrackModel, sleeper: int, side: str) -> float:
    """Lateral position [m] of the seat of the rail a wheel on ``side`` runs on at that sleeper."""
    x = model.layout.sleepers[sleeper].x
    body = model.layout.running_body(side, x)
    ys = [y for s, r, y in zip(model.pads.sleeper, model.pads.rail, model.pads.y) if s == sleeper and r == body]
    return float(np.mean(ys))


def side_region(y_p: np.ndarray, y_seat: float) -> np.ndarray:
    """Bushings under a rail seat: those within SIDE_WINDOW of ``y_seat`` [m], else the nearest one.

    Parameters
    ----------
    y_p : ndarray, shape (nb,)
        Lateral positions of a sleeper's ballast bushings [m] (nb >= 1).
    y_seat : float
        Lateral position of the rail seat [m].

    Returns
    -------
    ndarray of bool, shape (nb,)
        Never empty: bushings coarser than the window still give the seat a pressure.
    """
    d = np.abs(np.asarray(y_p, float) - y_seat)
    near = d <= SIDE_WINDOW
    if not near.any():
        near = d == d.min()
    return near


def analysis_columns(model: TrackModel) -> dict:
    """The columns of the track states :func:`analyse` reads (a ``record_columns`` request).

    q: the generalized coordinates of the crossing rail and of the transition sleeper
    (their recovered fields, ``track.post.body_response``) and the sleeper nodes of the
    ballast bushings under that sleeper (``track.post.sleeper_pressure``); v: those nodes.

    Returns
    -------
    dict
        ``{"q": ..., "v": ...}``, sorted column indices (ndarray of int).
    """
    side, x_ref, k_tr = reference_point(model)
    rail = model.body(model.layout.running_body(side, x_ref))
    sleeper = model.body(f"sleeper_{k_tr}")
    D = np.unique(model.ballast.dof[model.ballast.sleeper == k_tr])
    return {"q": np.union1d(np.union1d(rail.gdofs, sleeper.gdofs), D), "v": D}


def _histories(model: TrackModel, rec: dict, rail_name: str, k_tr: int, load_x: np.ndarray):
    """Moment history along the rail (nt, nn), the sleeper's response and its ballast pressures
    (y [m], p (nt, nb) [Pa]) from the record, a block of :data:`STATE_BLOCK` rows at a time;
    ``load_x``: the wheels' x on the rail, NaN where a wheel is on another body (:func:`_on_rail`)."""
    n, nt = model.n, len(rec["t"])
    rail_M, sl_w, sl_M, p_t = [], [], [], []
    y_p = sl = None
    for b in range(0, nt, STATE_BLOCK):
        rows = slice(b, b + STATE_BLOCK)
        q, v = state_rows(rec, "q", n, rows), state_rows(rec, "v", n, rows)
        rail_M.append(body_response_history(model, rail_name, q, load_x[rows], -rec["Fz"][rows]).moment)
        sl = body_response(model, f"sleeper_{k_tr}", q)
        sl_w.append(sl.w)
        sl_M.append(sl.moment)
        y_p, p = sleeper_pressure(model, k_tr, q, v)
        p_t.append(p)
    sleeper = BodyResponse(coord=sl.coord, w=np.concatenate(sl_w), moment=np.concatenate(sl_M))
    return np.concatenate(rail_M), sleeper, y_p, np.concatenate(p_t)


def _on_rail(model: TrackModel, rail_name: str, sides: list[str], xs: np.ndarray) -> np.ndarray:
    """The wheels' x (nt, m) where each runs on ``rail_name``, NaN where on another body."""
    lay = model.layout
    on = np.array([[lay.running_body(sd, x) == rail_name for sd, x in zip(sides, row)] for row in xs.tolist()],
                  dtype=bool).reshape(xs.shape)
    return np.where(on, xs, np.nan)


def analyse(model: TrackModel, static_wheel_load: float, res) -> Analysis:
    """Scalars and arrays of a co-simulation result (needs ``res.track_record``: all columns of
    q and v, or at least those of :func:`analysis_columns`)."""
    side, x_ref, k_tr = reference_point(model)
    m = res.Fz.shape[1]
    sides = wheel_sides(m)
    Fz = res.Fz[1:] if res.Fz.shape[0] > 1 else res.Fz   # row 0 is the static start
    out = Analysis()
    s = out.scalars
    cross = [i for i in range(m) if sides[i] == side]
    s["max_Fz"] = float(np.nanmax(Fz[:, cross]))
    s["min_Fz"] = float(np.nanmin(Fz[:, cross]))
    s["delta_Q"] = s["max_Fz"] - static_wheel_load
    s["max_Fz_nose"] = float(np.nanmax(res.parts[1:, cross, 1])) if res.parts.shape[0] > 1 else 0.0
    rec = res.track_record
    if rec is None or not len(rec.get("t", ())):
        return out
    lay = model.layout
    rail_name = lay.running_body(side, x_ref)
    load_x = _on_rail(model, rail_name, sides, np.asarray(rec["x"], float))
    rail_hist, sl, y_p, p_t = _histories(model, rec, rail_name, k_tr, load_x)
    j_r, j_s = int(np.argmax(rail_hist.max(axis=1))), int(np.argmax(sl.moment.max(axis=1)))
    y_cross, y_field = seat_y(model, k_tr, side), seat_y(model, k_tr, "right" if side == "left" else "left")
    near_c, near_f = side_region(y_p, y_cross), side_region(y_p, y_field)
    s.update({
        "max_rail_moment": float(rail_hist.max()), "time_max_rail_moment": float(rec["t"][j_r]),
        "max_sleeper_moment": float(sl.moment.max()), "time_max_sleeper_moment": float(rec["t"][j_s]),
        "max_ballast_pressure": float(p_t.max()),
        "max_ballast_pressure_crossing_side": float(p_t[:, near_c].max()),
        "max_ballast_pressure_field_side": float(p_t[:, near_f].max()),
        # at the instant of maximum sleeper moment (seed 001 Fig. 6 compares these)
        "ballast_pressure_crossing_side_at_max_sleeper": float(p_t[j_s, near_c].max()),
        "ballast_pressure_field_side_at_max_sleeper": float(p_t[j_s, near_f].max()),
    })
    rail_at = body_response_history(model, rail_name, state_rows(rec, "q", model.n, slice(j_r, j_r + 1)),
                                    load_x[j_r:j_r + 1], -rec["Fz"][j_r:j_r + 1])
    a = out.arrays
    a.update({
        "rail_x": rail_at.coord, "rail_w_at_max": rail_at.w[0], "rail_M_at_max": rail_at.moment[0],
        "rail_M_min": rail_hist.min(axis=0), "rail_M_max": rail_hist.max(axis=0),
        "sleeper_y": sl.coord, "sleeper_w_at_max": sl.w[j_s], "sleeper_M_at_max": sl.moment[j_s],
        "sleeper_M_min": sl.moment.min(axis=0), "sleeper_M_max": sl.moment.max(axis=0),
        "ballast_y": y_p, "ballast_p_at_max_sleeper": p_t[j_s], "ballast_p_max": p_t.max(axis=0),
        "wheel_y": np.array([y_cross, y_field]), "x_transition": np.array([x_ref]),
    })
    out.meta = {"crossing_rail": rail_name, "transition_sleeper": k_tr, "crossing_side": side,
                "j_rail": j_r, "j_sleeper": j_s, "rail_hist": rail_hist, "sleeper": sl,
                "y_p": y_p, "p_t": p_t}
    return out


SURFACE_NAMES = ("rail", "nose")   # parts[..., 0]: the running or wing rail; parts[..., 1]: the nose


def profile_contact(contact, model: TrackModel, res) -> tuple[dict, dict]:
    """Contact geometry outputs of a run with ``track.crossing.geometry: profiles``.

    Per wheel and surface (:func:`track.cosim.profile_outputs` at the recorded x and surface
    forces): lateral contact position on the rail, rolling radius, Hertz semi-axes a, b and peak
    pressure p0; per wheel that passes the nose, the impact angle emerging from its recorded
    vertical path (:func:`track.cosim.emergent_impact_angle`) next to the kinematic one of the
    contact table (:func:`track.contact_geometry.transfer`, rigid track, no dynamics).

    Returns
    -------
    arrays : dict
        ``eta``, ``radius``, ``a``, ``b``, ``p0``: (nt, m, 2) [m, m, m, m, Pa] (results.h5
        ``contact_geometry/``).
    summary : dict
        ``wheel<i>`` -> ``{surface: {max_p0, and eta, radius, a, b at the largest force}}``, plus
        ``transfer`` for the wheels on the crossing side.
    """
    from track.contact_geometry import transfer
    from track.cosim import contact_tables, emergent_impact_angle, profile_outputs

    arrays = profile_outputs(model, contact, res.x, res.parts)
    summary: dict = {}
    m = res.x.shape[1]
    crossing, _ = contact_tables(model, contact)
    sides = wheel_sides(m)
    for i in range(m):
        w: dict = {}
        for k, name in enumerate(SURFACE_NAMES):
            F = res.parts[:, i, k]
            if not (F > 0).any():
                continue
            j = int(np.nanargmax(F))
            w[name] = {"max_force": float(F[j]), "max_p0": float(np.nanmax(arrays["p0"][:, i, k])),
                       **{q: float(arrays[q][j, i, k]) for q in ("eta", "radius", "a", "b", "p0")}}
        if crossing is not None and sides[i] == model.layout.crossing_side:
            em = emergent_impact_angle(res.x[:, i], res.z[:, i], res.parts[:, i, 1], res.parts[:, i, 0])
            iy = int(np.argmin(np.abs(crossing.table.y - contact.lateral_offset)))
            kin = transfer(crossing.table, iy)
            w["transfer"] = {"emergent": em, "kinematic": {"x_transfer": kin["x"], "angle": kin["angle"],
                                                           "tip_impact": kin["tip_impact"]}}
        summary[f"wheel{i + 1}"] = w
    return arrays, summary


def profile_scalars(contact, model: TrackModel, res) -> dict:
    """Scalars of a profile-contact run for studies: for the first wheel at the nose, the emergent and
    kinematic impact angles [rad], the transfer position behind the theoretical crossing point [m],
    the peak nose force [N] and peak pressure [Pa] (:func:`profile_contact`); empty without a nose."""
    _, summary = profile_contact(contact, model, res)
    for w in summary.values():
        if "transfer" in w:
            em, kin = w["transfer"]["emergent"], w["transfer"]["kinematic"]
            nose = w.get("nose", {})
            return {"impact_angle_emergent": float(em["angle"]), "impact_angle_kinematic": float(kin["angle"]),
                    "transfer_behind_tcp": float(em["x_transfer"] - model.layout.x_tcp),
                    "max_Fz_nose_wheel": float(nose.get("max_force", 0.0)),
                    "max_p0_nose": float(nose.get("max_p0", np.nan))}
    return {}
