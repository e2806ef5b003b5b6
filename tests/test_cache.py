"""Reduced bodies are cached and reused when only bushing parameters change (seed 000 §5.4)."""
from track.model import build_track, clear_rom_cache
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
