"""Reduced bodies are cached and reused when only bushing parameters change (seed 000 §5.4)."""
from track.model import ROM_SUFFIX, build_track, clear_rom_cache
from track.params import BallastParams, LayoutParams, RailPadParams, TrackParams, VoidSpec


def test_bushing_changes_reuse_every_reduced_body():
    lp = LayoutParams(type="plain", sleepers=10)
    clear_rom_cache()
    a = build_track(TrackParams(layout=lp))
    assert a.stats.reductions >= 1
    b = build_track(TrackParams(layout=lp, rail_pad=RailPadParams(stiffness_scale=3.0),
                                ballast=BallastParams(stiffness_scale=0.5, voids=(VoidSpec(4, (1e-3,) * 6),))))
    assert b.stats.reductions == 0 and b.stats.cache_hits == b.stats.bodies
    assert b.n == a.n
    # ... but the bushings did change
    assert (b.pads.k == 3.0 * a.pads.k).all()
    # a geometric change (sleeper spacing) does need new reductions
    c = build_track(TrackParams(layout=LayoutParams(type="plain", sleepers=10, sleeper_spacing=0.65)))
    assert c.stats.reductions >= 1


def test_reduced_bodies_from_the_disk_cache_are_the_reduced_bodies(tmp_path):
    """A new process (here: the memory cache cleared) reads the reduced bodies from ``cache_dir``
    instead of reducing them again, and gets the same model to the bit (consistency check:
    the arrays are stored, not recomputed); an unreadable file is reduced again and rewritten;
    a folder that cannot be written to only costs the reductions; a body of the older .npz format is
    removed when a body is written."""
    import numpy as np

    lp = LayoutParams(type="plain", sleepers=8)
    clear_rom_cache()
    (tmp_path / "roms").mkdir()
    stale = tmp_path / "roms" / "rom-0000-0000.npz"     # a body in the format before 2026-11-27: removed
    stale.write_bytes(b"PK")
    a = build_track(TrackParams(layout=lp), cache_dir=tmp_path)
    assert not stale.exists()
    files = sorted((tmp_path / "roms").glob(f"rom-*{ROM_SUFFIX}"))
    assert a.stats.reductions >= 1 and len(files) == a.stats.reductions
    clear_rom_cache()
    b = build_track(TrackParams(layout=lp), cache_dir=tmp_path)
    assert b.stats.reductions == 0 and b.stats.cache_hits == b.stats.bodies
    for x, y in ((a.K, b.K), (a.M, b.M), (a.C, b.C)):
        assert (x != y).nnz == 0
    for ba, bb in zip(a.bodies, b.bodies):
        assert np.array_equal(ba.rom.T, bb.rom.T) and np.array_equal(ba.rom.mode_freqs, bb.rom.mode_freqs)
        if ba.rom.K_II_factor is not None:
            assert np.array_equal(ba.rom.K_II_factor[0], bb.rom.K_II_factor[0])
    files[0].write_bytes(b"not a reduced body")
    clear_rom_cache()
    c = build_track(TrackParams(layout=lp), cache_dir=tmp_path)
    assert c.stats.reductions == 1 and (c.K != a.K).nnz == 0
    assert files[0].stat().st_size > 100          # rewritten
    blocked = tmp_path / "file"
    blocked.write_text("a file where the cache folder should be")
    clear_rom_cache()
    d = build_track(TrackParams(layout=lp), cache_dir=blocked)
    assert d.stats.reductions == a.stats.reductions and (d.K != a.K).nnz == 0
