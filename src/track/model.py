"""Assembly of the reduced track model from a layout.

Pipeline: :func:`track.layout.build_layout` → FE beam bodies
(:mod:`track.bodies`) → Craig–Bampton per body (:mod:`track.reduction`, cached) →
global reduced ``M``, ``K``, ``C`` with rail pads (linear Kelvin bushings) and the
bi-linear ballast bushings (:class:`track.ballast.Ballast`, kept apart because they
are nonlinear).

Global coordinates are the union of every body's reduced coordinates; boundary
coordinates of rail ends joined at a :class:`track.layout.Joint` share one global
coordinate (a rigid weld).

``params.model == "solid"``: the part of the crossing block around the wheel
transfer is a reduced 3D solid (:mod:`track.solid.crossing`, body ``crossing``)
between two beam parts of the block (``crossing_front``, ``crossing_rear``); its
end couplings' ``(w, theta)`` are joint coordinates shared with their end nodes,
and its seats are two bushings each. Everything else is the beam model.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from .ballast import Ballast
from .bodies import BeamBody, beam_body, mesh_line
from .layout import Joint, Layout, RailBody, RunningSegment, build_layout
from .params import GRAVITY, TrackParams
from .reduction import ReducedBody, craig_bampton, element_residual, static_correction


@dataclass
class Body:
    """One reduced body in the assembled model.

    Attributes
    ----------
    name : str
    kind : str
        ``rail`` | ``crossing`` | ``check`` | ``sleeper``.
    origin : float
        Track coordinate of s = 0: x_start for rails, y_start for sleepers [m].
    x : float
        For sleepers the track coordinate of the sleeper [m]; NaN for rails.
    sleeper : int
        Sleeper index, -1 for rails.
    fom : BeamBody or track.solid.crossing.SolidCrossing
        The full-order model; a ``SolidCrossing`` for the solid crossing rail.
    rom : ReducedBody
        For the solid, ``T`` recovers the solid's displacements (3 per node).
    gdofs : ndarray of int, shape (nr,)
        Global index of each reduced coordinate.
    """

    name: str
    kind: str
    origin: float
    x: float
    sleeper: int
    fom: BeamBody
    rom: ReducedBody
    gdofs: np.ndarray

    @property
    def solid(self) -> bool:
        """True for the 3D solid crossing rail (:mod:`track.solid.crossing`)."""
        return not isinstance(self.fom, BeamBody)

    def local(self, coord: float) -> float:
        """Body coordinate s [m] of a track coordinate (x for rails, y for sleepers)."""
        return coord - self.origin

    def coords(self) -> np.ndarray:
        """Track coordinates of the FE nodes [m] (x for rails, y for sleepers).

        For the solid: of its output stations (:attr:`SolidCrossing.station_s`).
        """
        return self.origin + (self.fom.station_s if self.solid else self.fom.s)

    def point_nodes(self) -> np.ndarray:
        """Body coordinates s [m] of the nodes a point is interpolated between: the FE nodes
        of a beam, the contact-path nodes of the solid (element ``e`` spans nodes e, e+1)."""
        return self.fom.contact_s if self.solid else self.fom.s

    def point_row(self, s: float) -> tuple[int, np.ndarray]:
        """Element and interpolation weights of the point at body coordinate ``s`` [m] (clipped):
        beam shape functions on the element's 4 dofs (:meth:`BeamBody.shape_row`), or linear
        weights on the solid's 2 path nodes (:meth:`SolidCrossing.path_row`)."""
        return self.fom.path_row(s) if self.solid else self.fom.shape_row(s)

    def point_rows(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`point_row` for an array of body coordinates ``s`` [m], shape (k,): elements (k,)
        and weights (k, 4) (the solid's 2 linear weights in the first two columns)."""
        s = np.asarray(s, dtype=float)
        if not self.solid:
            return self.fom.shape_rows(s)
        cs = self.fom.contact_s
        e = np.clip(np.searchsorted(cs, s, side="right") - 1, 0, cs.size - 2)
        t = np.clip((s - cs[e]) / (cs[e + 1] - cs[e]), 0.0, 1.0)
        w = np.zeros((s.size, 4))
        w[:, 0], w[:, 1] = 1.0 - t, t
        return e, w

    def residual_block(self, element: int) -> np.ndarray:
        """The 4x4 residual flexibility [m/N] of a beam element's dofs (computed once, cached);
        zeros for the solid (no residual flexibility on its retained path nodes)."""
        if self.solid:
            return np.zeros((4, 4))
        blocks = self.rom.residual_blocks
        R = blocks.get(element)
        if R is None:
            R = blocks[element] = element_residual(self.rom, np.arange(2 * element, 2 * element + 4))
        return R

    def load_rows(self, element: int) -> np.ndarray:
        """Rows of ``T`` (k, nr) on which a point load in ``element`` acts.

        Beam: the 4 dofs of the element (weights: :meth:`BeamBody.shape_row`);
        solid: the two contact-path nodes of the segment (:meth:`SolidCrossing.path_row`).
        """
        if self.solid:
            return self.fom.segment_rows(element)
        return self.rom.T[2 * element:2 * element + 4, :]


@dataclass(slots=True)
class PointMap:
    """Vertical displacement of one material point as a linear map of q.

    ``w = weights @ q[gidx]``; a force F at the point adds ``F * weights`` to the
    generalized forces at ``gidx``. A force F acting *at* the point also deflects it
    locally by ``residual * F`` (the static part of the truncated modes,
    :func:`track.reduction.static_correction`), so the displacement under a load
    is ``weights @ q[gidx] + residual * F``.
    """

    body: str
    coord: float
    gidx: np.ndarray
    weights: np.ndarray
    residual: float = 0.0  # m/N
    element: int = -1          # FE element of the body the point lies in
    shape: np.ndarray | None = None  # its 4 deflection shape-function values

    def value(self, q: np.ndarray, force: float = 0.0) -> float:
        """Displacement [m] for state q, with a force [N] acting at the point itself."""
        return float(self.weights @ q[self.gidx]) + self.residual * force


@dataclass
class Pads:
    """Linear rail-pad bushings between a rail dof ``i`` and a sleeper dof ``j``."""

    i: np.ndarray
    j: np.ndarray
    k: np.ndarray  # N/m
    c: np.ndarray  # N s/m
    sleeper: np.ndarray
    rail: tuple
    y: np.ndarray  # lateral position of the bushing on the sleeper [m]


@dataclass
class BuildStats:
    """Sizes and one-time costs of a model build."""

    fom_dofs: int = 0
    rom_dofs: int = 0
    bodies: int = 0
    reductions: int = 0
    cache_hits: int = 0
    t_mesh_assembly: float = 0.0
    t_reduction: float = 0.0
    t_global: float = 0.0
    t_solid_mesh: float = 0.0       # solid crossing rail: gmsh + assembly + tie + Craig–Bampton [s] (0 if cached)
    t_solid_reduction: float = 0.0  # its output rows: section deflections and moments [s] (0 if cached)


@dataclass
class TrackModel:
    """The assembled reduced track.

    Attributes
    ----------
    params : TrackParams
    layout : Layout
    bodies : list of Body
    n : int
        Number of global reduced coordinates.
    M, K, C : scipy.sparse.csr_matrix, shape (n, n)
        Bodies plus rail pads; the ballast is in ``ballast``.
    f_gravity : ndarray, shape (n,)
        Self-weight of rails and sleepers as generalized forces [N].
    pads : Pads
    ballast : Ballast
    stats : BuildStats
    """

    params: TrackParams
    layout: Layout
    bodies: list
    n: int
    M: sp.csr_matrix
    K: sp.csr_matrix
    C: sp.csr_matrix
    f_gravity: np.ndarray
    pads: Pads
    ballast: Ballast
    stats: BuildStats
    _index: dict = field(default_factory=dict, repr=False)

    def body(self, name: str) -> Body:
        k = self._index.get(name)
        if k is None:
            raise KeyError(f"no body named {name!r}")
        return self.bodies[k]

    def sleeper(self, index: int) -> Body:
        return self.body(f"sleeper_{index}")

    def point(self, body: str, coord: float) -> PointMap:
        """Map of the vertical displacement at track coordinate ``coord`` on ``body``.

        ``coord`` is x [m] for rails and y [m] for sleepers; it is clipped to the body.
        """
        b = self.body(body)
        e, w = b.point_row(coord - b.origin)
        if b.solid:   # linear between two retained contact-path nodes: no residual flexibility
            return PointMap(body, coord, b.gdofs, w @ b.fom.segment_rows(e), 0.0, e, w)
        R = b.residual_block(e)
        return PointMap(body, coord, b.gdofs, w @ b.rom.T[2 * e:2 * e + 4, :], float(w @ R @ w), e, w)

    def rail_point(self, side: str, x: float) -> PointMap:
        """Map of the running rail under a wheel on ``side`` at track coordinate x [m]."""
        return self.point(self.layout.running_body(side, x), x)

    def full_field(self, body: str, q: np.ndarray, loads=()) -> np.ndarray:
        """Full FE displacement of one body, shape (..., 2 n_nodes).

        ``u = T q`` plus, for point loads ``[(PointMap, F), ...]`` acting on this body
        (F shape () or (nt,) matching q's leading axis), the static correction of the
        truncated modes (:func:`track.reduction.static_correction`). For the solid
        crossing rail the solid's displacements, shape (..., 3 n_nodes) (its wheel loads
        act on retained nodes and need no correction).
        """
        b = self.body(body)
        u = np.asarray(q)[..., b.gdofs] @ b.rom.T.T
        if b.solid:
            return u
        for pm, F in loads:
            if pm.body != body:
                continue
            e, w = b.fom.shape_row(b.local(pm.coord))
            f = np.zeros(b.fom.ndof)
            f[2 * e:2 * e + 4] = w
            u = u + np.multiply.outer(np.asarray(F, float), static_correction(b.rom, f))
        return u

    def tangent(self, q: np.ndarray, v: np.ndarray | None = None):
        """Stiffness and damping linearized at state q (ballast in its current contact state)."""
        kb, cb = self.ballast.tangent(q[self.ballast.dof], None if v is None else v[self.ballast.dof])
        D = self.ballast.dof
        Kb = sp.csr_matrix((kb, (D, D)), shape=(self.n, self.n))
        Cb = sp.csr_matrix((cb, (D, D)), shape=(self.n, self.n))
        return (self.K + Kb).tocsr(), (self.C + Cb).tocsr()


# --------------------------------------------------------------------------- reduction cache
_ROM_CACHE: dict = {}
ROM_CACHE_MAX = 4096  # bodies kept in memory (a 40-sleeper panel has ~50)


def _rom_key(s: np.ndarray, profile, boundary: np.ndarray, f_modes: float, empty: tuple = ()) -> str:
    h = hashlib.sha1()
    h.update(np.round(s, 9).tobytes())
    h.update(repr(profile).encode())
    if empty:    # only then: the keys of every other body stay what they were
        h.update(repr(tuple(round(float(v), 9) for span in empty for v in span)).encode())
    h.update(np.asarray(boundary, np.int64).tobytes())
    h.update(repr(float(f_modes)).encode())
    return h.hexdigest()


def clear_rom_cache() -> None:
    """Forget every cached reduced body."""
    _ROM_CACHE.clear()


def _reduce_cached(fom: BeamBody, boundary: np.ndarray, f_modes: float, stats: BuildStats,
                   cache_dir=None) -> ReducedBody:
    """The Craig–Bampton body of ``fom``: from memory, from the disk cache in ``cache_dir``
    (:func:`_rom_load`), or reduced (and kept in both)."""
    key = _rom_key(fom.s, fom.profile, boundary, f_modes, fom.empty)
    rom = _ROM_CACHE.get(key)
    if rom is not None:
        stats.cache_hits += 1
        return rom
    path = None if cache_dir is None else Path(cache_dir) / ROM_DISK_FOLDER / f"rom-{key}-{_code_version()}{ROM_SUFFIX}"
    rom = _rom_load(path) if path is not None else None
    if rom is not None:
        stats.cache_hits += 1
    else:
        rom = craig_bampton(fom.K, fom.M, boundary, f_modes=f_modes)
        stats.reductions += 1
        if path is not None:
            _rom_save(rom, path)
    if len(_ROM_CACHE) >= ROM_CACHE_MAX:
        _ROM_CACHE.pop(next(iter(_ROM_CACHE)))
    _ROM_CACHE[key] = rom
    return rom


# --------------------------------------------------------------------------- reduction cache on disk
# A process's first build of a track reduces ~45 bodies (0.5 s of the default scenario's
# 0.6 s build) — and a run builds its track twice: the orchestrator's post-processing and
# the track FMU each have their own copy. Reduced bodies are kept in ``cache_dir/roms`` as
# one file each (arrays only, readable by any copy of this package), under the key of the
# body and a hash of the sources that make them, so a change of the FE or reduction code
# never reads an old body. The file (:func:`_rom_save`) is a JSON list of the arrays' names,
# dtypes and shapes, then their bytes, each at a multiple of 64: read as one buffer and
# viewed (:func:`_rom_load`), 45 bodies take ~5 ms against ~50-110 ms as .npz (numpy parses
# every member's header with ``ast``; measured 2026-11-27), twice per ``turnout run``.
ROM_DISK_FOLDER = "roms"
ROM_SUFFIX = ".rom"
_ROM_MAGIC = b"turnout-rom-1\n"
_ROM_ALIGN = 64
ROM_DISK_MAX = 4000          # files kept (a 40-sleeper panel has ~45 bodies of ~50-300 kB); oldest go first
_ROM_SOURCES = ("bodies.py", "elements.py", "reduction.py", "params.py")
_ROM_FIELDS = ("K", "M", "T", "boundary", "mode_freqs", "interior", "modes_I")
_CODE_VERSION: list = []


def _code_version() -> str:
    """Hash of the sources a reduced body is made from (:data:`_ROM_SOURCES`), once per process."""
    if not _CODE_VERSION:
        h = hashlib.sha1()
        here = Path(__file__).resolve().parent
        for name in _ROM_SOURCES:
            h.update((here / name).read_bytes())
        _CODE_VERSION.append(h.hexdigest()[:12])
    return _CODE_VERSION[0]


def _rom_save(rom: ReducedBody, path: Path) -> None:
    """Write ``rom`` to ``path`` atomically (format: the section's comment); a cache that cannot be
    written is skipped."""
    arrays = {k: getattr(rom, k) for k in _ROM_FIELDS if getattr(rom, k) is not None}
    if rom.K_II_factor is not None:
        arrays["K_II_c"], arrays["K_II_lower"] = rom.K_II_factor[0], np.array(bool(rom.K_II_factor[1]))
    arrays = {k: np.ascontiguousarray(v) for k, v in arrays.items()}
    header = json.dumps([[k, v.dtype.str, list(v.shape)] for k, v in arrays.items()]).encode()
    head = _ROM_MAGIC + len(header).to_bytes(8, "little") + header
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp")
        with open(tmp, "wb") as fh:
            fh.write(head)
            for v in arrays.values():
                fh.write(b"\0" * (-fh.tell() % _ROM_ALIGN))
                fh.write(v.tobytes())
        os.replace(tmp, path)
        files = sorted(path.parent.glob(f"rom-*{ROM_SUFFIX}"), key=lambda f: f.stat().st_mtime)
        for old in files[:max(0, len(files) - ROM_DISK_MAX)] + list(path.parent.glob("rom-*.npz")):
            old.unlink(missing_ok=True)   # and the .npz files of the format before 2026-11-27, never read now
    except OSError:
        pass


def _rom_load(path: Path) -> ReducedBody | None:
    """The body stored at ``path`` (:func:`_rom_save`); None if it is missing, unreadable or not
    whole (it is then rebuilt). The arrays are views on one writable buffer."""
    try:
        buf = np.fromfile(path, dtype=np.uint8)
        m = len(_ROM_MAGIC)
        if buf[:m].tobytes() != _ROM_MAGIC:
            return None
        n = int.from_bytes(buf[m:m + 8].tobytes(), "little")
        at = m + 8 + n
        arrays = {}
        for name, dtype, shape in json.loads(buf[m + 8:at].tobytes()):
            at += -at % _ROM_ALIGN
            dt = np.dtype(dtype)
            size = dt.itemsize * math.prod(shape)
            if dt.hasobject or at + size > buf.size:
                return None
            arrays[name] = buf[at:at + size].view(dt).reshape(shape)
            at += size
        kw = {k: arrays[k] for k in _ROM_FIELDS if k in arrays}
        if "K_II_c" in arrays:
            kw["K_II_factor"] = (arrays["K_II_c"], bool(arrays["K_II_lower"]))
        os.utime(path)      # recently used: kept by the eviction in _rom_save
        return ReducedBody(**kw)
    except (OSError, ValueError, KeyError, TypeError, IndexError):
        return None


# --------------------------------------------------------------------------- build
def _pad_seat_points(seat, kind: str, two_bushings: bool, solid_offset: float | None = None
                     ) -> list[tuple[float, float, int]]:
    """Lateral positions, stiffness shares and bushing index of the bushing(s) of one rail seat.

    ``solid_offset``: the seat is under the solid crossing rail, whose two bushings sit
    at ``-b, +b`` [m] across the foot (always two).
    """
    if solid_offset is not None:
        return [(seat.y - solid_offset, 0.5, 0), (seat.y + solid_offset, 0.5, 1)]
    if kind == "crossing" and two_bushings:
        half = 0.5 * seat.width
        return [(seat.y - half, 0.5, 0), (seat.y + half, 0.5, 1)]
    return [(seat.y, 1.0, 0)]


def _split_crossing(lay: Layout, params: TrackParams, cache_dir=None):
    """The layout with the crossing block split into beam / solid / beam parts, and the solid.

    Returns ``(layout, solid)``: the solid part keeps the name ``crossing`` (it carries
    the nose and the transition); ``crossing_front`` and ``crossing_rear`` are the beam
    parts of the block ahead of and behind it (left out when empty).
    """
    from .solid.crossing import solid_crossing, solid_extent, solid_params

    if lay.x_transition is None:
        raise ValueError("model: 'solid' (3D crossing rail) needs a turnout layout")
    blk = lay.rail("crossing")
    x_a, x_b = solid_extent(lay, lay.params.sleeper_spacing)
    eps = 1e-6

    def part(name, x0, x1, seats):
        d = x0 - blk.x_start
        prof = replace(blk.profile, s=tuple(float(v) - d for v in blk.profile.s))
        return RailBody(name, "crossing", x0, x1, prof, tuple(seats))

    inner = [st for st in blk.seats if x_a + eps < st.x < x_b - eps]
    parts = []
    if x_a - blk.x_start > eps:
        parts.append(part("crossing_front", blk.x_start, x_a, [st for st in blk.seats if st.x <= x_a + eps]))
    parts.append(part("crossing", x_a, x_b, inner))
    if blk.x_end - x_b > eps:
        parts.append(part("crossing_rear", x_b, blk.x_end, [st for st in blk.seats if st.x >= x_b - eps]))
    names = [p_.name for p_ in parts]
    rails = []
    for r in lay.rails:
        rails.extend(parts if r.name == "crossing" else [r])
    first, last = names[0], names[-1]
    joints = [Joint(j.x, tuple(((first if e == "start" else last), e) if n == "crossing" else (n, e)
                               for n, e in j.ends)) for j in lay.joints]
    for a, b in zip(parts[:-1], parts[1:]):
        joints.append(Joint(a.x_end, ((a.name, "end"), (b.name, "start"))))
    running = {}
    for side, segs in lay.running.items():
        out = []
        for sg in segs:
            if sg.body == "crossing":
                out.extend(RunningSegment(p_.name, max(sg.x0, p_.x_start), min(sg.x1, p_.x_end)) for p_ in parts)
            else:
                out.append(sg)
        running[side] = tuple(out)
    red = params.reduction
    sp_ = solid_params(lay, blk.profile, blk.x_start, x_a, x_b, [st.x for st in inner],
                       red.solid_mesh_size, red.f_cut, red.element_length)
    return replace(lay, rails=tuple(rails), joints=tuple(joints), running=running), solid_crossing(sp_, cache_dir)


def reference_point(model: TrackModel) -> tuple[str, float, int]:
    """(crossing-side wheel, x of the crossing transition, transition sleeper index).

    Plain track: the left side and the middle sleeper.
    """
    lay = model.layout
    if lay.x_transition is not None:
        k = lay.params.transition_sleeper
        k = len(lay.sleepers) // 2 + 1 if k is None else k
        return lay.crossing_side, lay.x_transition, k
    k = len(lay.sleepers) // 2
    return "left", lay.sleepers[k].x, k


def rail_parts(model: TrackModel, name: str) -> list[str]:
    """The bodies that model the layout rail ``name``, in increasing ``x``.

    ``[name]`` for a rail modelled as one body; with ``model: solid`` the crossing block
    (``crossing``) is three: ``crossing_front``, ``crossing`` (the solid), ``crossing_rear``
    (:func:`_split_crossing`). Empty if the model has no such rail.
    """
    names = [name, f"{name}_front", f"{name}_rear"]
    parts = [b for b in model.bodies if b.name in names and b.sleeper < 0]
    if not any(b.name == name for b in parts):
        return []
    return [b.name for b in sorted(parts, key=lambda b: b.origin)]


@dataclass
class _BodySpec:
    """A body before reduction: its FE model and the dofs it keeps.

    Attributes
    ----------
    name, kind : str
    origin : float
        Body coordinate origin [m] (rail: x of its start; sleeper: y of its end).
    x : float
        Sleeper position along the track [m] (NaN for rails).
    sleeper : int
        Sleeper index (-1 for rails).
    fom : BeamBody or SolidCrossing
        The full-order model (the solid comes already reduced).
    boundary : ndarray or None
        Retained dofs of a beam body (None for the solid).
    keys : list of tuple
        Global keys of the retained coordinates (joints alias them).
    """

    name: str
    kind: str
    origin: float
    x: float
    sleeper: int
    fom: object
    boundary: np.ndarray | None
    keys: list


def build_track(params: TrackParams, layout: Layout | None = None, *, cache_dir=None) -> TrackModel:
    """Build the reduced track model.

    Stages: layout (and the solid crossing rail) -> rail-seat points -> FE bodies with
    their retained dofs -> Craig–Bampton per body (cached) -> global numbering (joints
    share coordinates) and assembly -> rail pads -> ballast bushings.

    Parameters
    ----------
    params : TrackParams
    layout : Layout, optional
        A precomputed layout of ``params.layout``.
    cache_dir : path-like, optional
        Folder of the on-disk caches: the solid crossing rail (``track.model: solid``; see
        :func:`track.cache.cache_dir_from_env`) and the reduced beam bodies
        (:func:`_reduce_cached`); None keeps them in memory only.

    Returns
    -------
    TrackModel
    """
    if params.model not in ("beam", "solid"):
        raise ValueError(f"model: must be 'beam' or 'solid', got {params.model!r}")
    stats = BuildStats()
    t0 = time.perf_counter()
    lay = layout if layout is not None else build_layout(params.layout)
    solid = None
    if params.model == "solid":
        lay, solid = _split_crossing(lay, params, cache_dir)
        if solid.from_cache:
            stats.cache_hits += 1
        else:
            stats.reductions += 1
            stats.t_solid_mesh, stats.t_solid_reduction = solid.t_mesh, solid.t_reduction
        t0 = time.perf_counter()
    seats_on = _seat_points(lay, params.rail_pad, solid)
    specs = _rail_specs(lay, solid, params.reduction.element_length)
    sleeper_specs, ballast_rows = _sleeper_specs(lay, seats_on, params, stats)
    specs += sleeper_specs
    stats.fom_dofs += sum(s.fom.ndof if s.boundary is not None else s.fom.fom_dofs
                          for s in specs if s.kind != "sleeper")
    stats.t_mesh_assembly = time.perf_counter() - t0

    t1 = time.perf_counter()
    f_modes = params.reduction.mode_factor * params.reduction.f_cut
    roms = [_reduce_cached(s.fom, s.boundary, f_modes, stats, cache_dir) if s.boundary is not None
            else _solid_rom(s.fom)
            for s in specs]
    stats.t_reduction = time.perf_counter() - t1

    t2 = time.perf_counter()
    bodies, n = _number(lay, specs, roms)
    index = {b.name: k for k, b in enumerate(bodies)}
    K, M, C, fg = _assemble(bodies, n, params.structural_damping)
    pads = _pads(lay, bodies, index, seats_on, params.rail_pad)
    K = K + _spring_matrix(pads.i, pads.j, pads.k, n)
    C = C + _spring_matrix(pads.i, pads.j, pads.c, n)
    ballast = _ballast(lay, bodies, index, ballast_rows, params.ballast)
    stats.t_global = time.perf_counter() - t2
    stats.rom_dofs = n
    stats.bodies = len(bodies)
    return TrackModel(params=params, layout=lay, bodies=bodies, n=n, M=M.tocsr(), K=K.tocsr(),
                      C=C.tocsr(), f_gravity=fg, pads=pads, ballast=ballast, stats=stats, _index=index)


def _seat_points(lay: Layout, pad, solid) -> list[list[tuple]]:
    """Rail-seat pad points per sleeper: ``(rail name, x, y, stiffness share, bushing index)``."""
    seats_on = [[] for _ in range(len(lay.sleepers))]
    for r in lay.rails:
        off = solid.params.bushing_offset if (solid is not None and r.name == "crossing") else None
        for seat in r.seats:
            for y, share, kb in _pad_seat_points(seat, r.kind, pad.two_bushings, off):
                seats_on[seat.sleeper].append((r.name, seat.x, y, share, kb))
    return seats_on


def _rail_specs(lay: Layout, solid, element_length: float) -> list[_BodySpec]:
    """The rails' FE bodies and retained dofs (deflection and rotation at every seat, joint ends)."""
    joint_ends = {(name, end) for j in lay.joints for name, end in j.ends}
    specs = []
    for r in lay.rails:
        if solid is not None and r.name == "crossing":
            nb = 4                          # q[:4]: (w, theta) of both end couplings, the joint coordinates
            if not np.array_equal(solid.end_q.ravel(), np.arange(nb)):
                raise RuntimeError("solid end coordinates are expected first in q")
            specs.append(_BodySpec(r.name, r.kind, r.x_start, np.nan, -1, solid, None,
                                   [(r.name, a) for a in range(nb)]))
            continue
        L = r.x_end - r.x_start
        seat_s = np.array([st.x - r.x_start for st in r.seats])
        fom = beam_body(r.name, mesh_line(L, seat_s, element_length), r.profile)
        bnodes = [fom.node(s) for s in seat_s]
        # deflection and rotation at every seat: the fixed-interface modes are then local
        # to one span (clamped-clamped) and the reduced rail matrices banded
        bdofs = [2 * i + d for i in bnodes for d in (0, 1)]
        keys = [(r.name, dof) for dof in bdofs]
        for end, node in (("start", 0), ("end", fom.s.size - 1)):
            if (r.name, end) in joint_ends:
                for d in (2 * node, 2 * node + 1):
                    if d not in bdofs:
                        bdofs.append(d)
                        keys.append((r.name, d))
        specs.append(_BodySpec(r.name, r.kind, r.x_start, np.nan, -1, fom, np.array(bdofs), keys))
    return specs


def _sleeper_specs(lay: Layout, seats_on, params: TrackParams, stats: BuildStats):
    """The sleepers' FE bodies (deflection retained at the seats and ballast points) and the
    ballast rows ``(sleeper, body name, y, tributary length, width)``."""
    bal, element_length = params.ballast, params.reduction.element_length
    specs, ballast_rows = [], []
    for sl in lay.sleepers:
        ys = np.array([y for _, _, y, _, _ in seats_on[sl.index]])
        nodes_s, yb_all = [], []
        for a, b in sl.pieces:           # one sleeper, or the two of a split position (the gap one element)
            L = b - a
            nb = max(2, int(np.ceil(L / bal.spacing - 1e-9)))
            trib = L / nb
            yb = a + trib * (np.arange(nb) + 0.5)
            mine = ys[(ys >= a - 1e-9) & (ys <= b + 1e-9)]
            nodes_s.append(a - sl.y_start + mesh_line(L, np.concatenate([mine, yb]) - a, element_length))
            yb_all += [(y, trib) for y in yb]
        empty = ((sl.gap[0] - sl.y_start, sl.gap[1] - sl.y_start),) if sl.gap else ()
        fom = beam_body(f"sleeper_{sl.index}", np.concatenate(nodes_s), sl.profile, empty)
        pts = np.concatenate([ys, [y for y, _ in yb_all]]) - sl.y_start
        nodes = sorted({fom.node(s) for s in pts})
        bdofs = [2 * i for i in nodes]
        name = f"sleeper_{sl.index}"
        specs.append(_BodySpec(name, "sleeper", sl.y_start, sl.x, sl.index, fom, np.array(bdofs),
                               [(name, d) for d in bdofs]))
        for y, trib in yb_all:
            ballast_rows.append((sl.index, name, y, trib, sl.profile.base.width))
        stats.fom_dofs += fom.ndof
    return specs, ballast_rows


def _number(lay: Layout, specs: list[_BodySpec], roms: list) -> tuple[list[Body], int]:
    """Global numbering of the reduced coordinates (joints alias the two rail ends) -> bodies, n."""
    alias = {}
    for j in lay.joints:
        for name, end in j.ends:
            fom = next(s.fom for s in specs if s.name == name)
            for d in (0, 1):
                if not isinstance(fom, BeamBody):      # the solid: q positions of its end couplings
                    key = (name, int(fom.end_q[0 if end == "start" else 1, d]))
                else:
                    key = (name, 2 * (0 if end == "start" else fom.s.size - 1) + d)
                alias[key] = ("joint", j.x, d)
    gid = {}
    n = 0
    bodies = []
    for s, rom in zip(specs, roms):
        g = np.empty(rom.nr, dtype=int)
        for a, key in enumerate(s.keys):
            key = alias.get(key, key)
            if key not in gid:
                gid[key] = n
                n += 1
            g[a] = gid[key]
        g[len(s.keys):] = n + np.arange(rom.nr - len(s.keys))
        n += rom.nr - len(s.keys)
        bodies.append(Body(s.name, s.kind, s.origin, s.x, s.sleeper, s.fom, rom, g))
    return bodies, n


def _assemble(bodies: list[Body], n: int, beta: float):
    """Global K, M, C = beta K (structural damping) and the gravity load f_g [N] of the bodies."""
    rows, cols, kv, mv = [], [], [], []
    fg = np.zeros(n)
    for b in bodies:
        r_, c_ = np.meshgrid(b.gdofs, b.gdofs, indexing="ij")
        rows.append(r_.ravel())
        cols.append(c_.ravel())
        kv.append(b.rom.K.ravel())
        mv.append(b.rom.M.ravel())
        if b.solid:
            np.add.at(fg, b.gdofs, -GRAVITY * b.fom.weight)
            continue
        unit = np.zeros(b.fom.ndof)
        unit[0::2] = 1.0
        np.add.at(fg, b.gdofs, -GRAVITY * (b.rom.T.T @ (b.fom.M @ unit)))
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    K = sp.csr_matrix((np.concatenate(kv), (rows, cols)), shape=(n, n))
    M = sp.csr_matrix((np.concatenate(mv), (rows, cols)), shape=(n, n))
    return K, M, beta * K, fg


def _pads(lay: Layout, bodies, index, seats_on, pad) -> Pads:
    """The rail-pad bushings between rail and sleeper coordinates (with the per-sleeper overrides)."""
    overrides = {o.sleeper: o.stiffness_scale for o in pad.overrides}
    pi, pj, pk, pc, psl, prl, py = [], [], [], [], [], [], []
    for sl in lay.sleepers:
        sb = bodies[index[f"sleeper_{sl.index}"]]
        for rname, x, y, share, kb in seats_on[sl.index]:
            rb = bodies[index[rname]]
            if rb.solid:
                seat = int(np.argmin(np.abs(rb.fom.seat_s - (x - rb.origin))))
                i = rb.gdofs[rb.fom.seat_q[seat, kb]]
            else:
                i = rb.gdofs[list(rb.rom.boundary).index(2 * rb.fom.node(x - rb.origin))]
            j = sb.gdofs[list(sb.rom.boundary).index(2 * sb.fom.node(y - sb.origin))]
            scale = pad.stiffness_scale * overrides.get(sl.index, 1.0)
            pi.append(i); pj.append(j); psl.append(sl.index); prl.append(rname); py.append(y)
            pk.append(share * pad.stiffness * scale)
            pc.append(share * pad.damping)
    return Pads(np.array(pi), np.array(pj), np.array(pk), np.array(pc), np.array(psl), tuple(prl), np.array(py))


def _ballast(lay: Layout, bodies, index, ballast_rows, bal) -> Ballast:
    """The bi-linear ballast bushings under the sleepers, each with its void gap [m]."""
    voids = {v.sleeper: np.asarray(v.gaps, float) for v in bal.voids}
    bdof, bk, bc, bgap, bsl, by, barea = [], [], [], [], [], [], []
    for sl_idx, name, y, trib, width in ballast_rows:
        sb = bodies[index[name]]
        bdof.append(sb.gdofs[list(sb.rom.boundary).index(2 * sb.fom.node(y - sb.origin))])
        bk.append(bal.stiffness_per_length * bal.stiffness_scale * trib)
        bc.append(bal.damping_per_length * trib)
        sl = lay.sleepers[sl_idx]
        g6 = voids.get(sl_idx)
        bgap.append(0.0 if g6 is None else float(np.interp(y, np.linspace(sl.y_start, sl.y_end, 6), g6)))
        bsl.append(sl_idx); by.append(y); barea.append(trib * width)
    return Ballast(dof=np.array(bdof), k=np.array(bk), c=np.array(bc), gap=np.array(bgap),
                   sleeper=np.array(bsl), y=np.array(by), area=np.array(barea))


def _solid_rom(sc) -> ReducedBody:
    """The solid crossing body's reduced matrices as a :class:`ReducedBody` (``T``: solid dofs)."""
    nm = sc.mode_freqs.size
    return ReducedBody(K=sc.K, M=sc.M, T=sc.T, boundary=np.arange(sc.nr - nm), mode_freqs=sc.mode_freqs)


def _spring_matrix(i: np.ndarray, j: np.ndarray, k: np.ndarray, n: int) -> sp.csr_matrix:
    """Stiffness (or damping) matrix of two-node springs between dofs i and j."""
    rows = np.concatenate([i, j, i, j])
    cols = np.concatenate([i, j, j, i])
    vals = np.concatenate([k, k, -k, -k])
    return sp.csr_matrix((vals, (rows, cols)), shape=(n, n))
