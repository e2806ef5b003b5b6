"""Precompute time of the contact geometry table of the default crossing panel (issue 15).

Target: <= 2 s for the default panel. The table covers the part of the panel where the
geometry differs from a plain rail for the wheel at the nose: from 0.1 m ahead of the throat
(where the wing rail starts to flare) to 0.1 m behind the end of the wing rails, in x steps of
5 mm (0.4 mm of wing-rail flare per step at 1:13), and lateral wheelset offsets -10 .. +10 mm
in 0.5 mm steps, two surfaces (wing rail, nose), new S1002 wheel, lateral sampling 0.1 mm.
Also prints the kinematic transfer (where the centred wheel moves to the nose, the nose width
there, the change of slope of the rigid wheel's path) for new and worn geometries.

Prints, and appends a dated section to benchmarks/RESULTS.md unless --no-record.

Run: python benchmarks/bench_contact_geometry.py [--repeat 3] [--no-record]
"""
from __future__ import annotations

import argparse
import datetime
import os
import platform
import time
from pathlib import Path

import numpy as np

from track.contact_geometry import crossing_table, transfer
from track.layout import CROSSING_WING_END, build_layout
from track.params import LayoutParams
from track.profiles import CrossingSections, WheelProfile

DX = 0.005            # m
Y = np.arange(-0.010, 0.010 + 1e-12, 0.0005)
TARGET = 2.0          # s


def machine() -> str:
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return (f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
            f"load average {load:.1f} (machine shared with other sessions)")


def default_grid(lay) -> np.ndarray:
    """The x grid of the default panel's table (module docstring)."""
    geo = lay.geometry()
    return np.arange(geo.x_throat - 0.1, lay.x_tcp + CROSSING_WING_END + 0.1, DX)


def time_table(repeat: int) -> tuple[float, int, int]:
    lay = build_layout(LayoutParams())
    x = default_grid(lay)
    cs = CrossingSections.from_layout(lay)
    wheel = WheelProfile()
    best = np.inf
    for _ in range(repeat):
        t = time.perf_counter()
        crossing_table(wheel, cs, x, Y)
        best = min(best, time.perf_counter() - t)
    return best, x.size, Y.size


def transfers() -> list[tuple[str, dict, float]]:
    """Kinematic transfer of the centred wheel for new and worn geometries."""
    lay = build_layout(LayoutParams())
    x = np.arange(lay.x_tcp - 0.2, lay.x_tcp + 1.0, 0.0025)
    cases = {
        "new S1002, nominal crossing": (WheelProfile(), {}),
        "nose height loss 1 mm (uniform)": (WheelProfile(), dict(nose_wear_stations=(0.0,), nose_wear=(0.001,))),
        "nose height loss 2 mm (uniform)": (WheelProfile(), dict(nose_wear_stations=(0.0,), nose_wear=(0.002,))),
        "hollow-worn wheel 2 mm": (WheelProfile(hollow_depth=0.002), {}),
        "flange thickness -3 mm": (WheelProfile(flange_thickness_change=-0.003), {}),
    }
    out = []
    for name, (wheel, kw) in cases.items():
        cs = CrossingSections.from_layout(lay, **kw)
        tab = crossing_table(wheel, cs, x, [0.0])
        tr = transfer(tab)
        zw = tab.data["z"][0, :, 0]
        depth = float(np.interp(tr["x"], x, zw)) if np.isfinite(tr["x"]) else float("nan")
        out.append((name, tr, float(cs.separation(tr["x"])) if np.isfinite(tr["x"]) else float("nan"), depth))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-record", action="store_true")
    a = ap.parse_args()
    best, nx, ny = time_table(a.repeat)
    rows = transfers()
    lines = [
        f"## Contact geometry table — {datetime.datetime.now():%Y-%m-%d %H:%M}, {machine()}",
        "",
        "`python benchmarks/bench_contact_geometry.py` (default 1:12 R500 panel, new S1002 on 60E1 sections; "
        f"x from 0.1 m ahead of the throat to 0.1 m behind the wing-rail ends in {DX * 1e3:.0f} mm steps, "
        "lateral offsets -10 .. +10 mm in 0.5 mm steps, wing rail and nose, lateral sampling 0.1 mm).",
        "",
        f"Precompute: **{best:.2f} s** (best of {a.repeat}) for {nx} x {ny} grid points x 2 surfaces; "
        f"target <= {TARGET:.0f} s: {'met' if best <= TARGET else 'NOT met'}.",
        "",
        "Kinematic transfer of the centred wheel (rigid wheel on rigid rails following the higher surface; "
        "not the dynamic impact angle):",
        "",
        "| case | nose width at transfer [mm] | wheel drop there [mm] | wing slope [mrad] | nose slope [mrad] "
        "| slope change [mrad] | tip impact |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, tr, w, depth in rows:
        lines.append(f"| {name} | {w * 1e3:.1f} | {-depth * 1e3:.2f} | {tr['slope_wing'] * 1e3:.1f} | "
                     f"{tr['slope_nose'] * 1e3:.1f} | {tr['angle'] * 1e3:.1f} | {tr['tip_impact']} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if not a.no_record:
        path = Path(__file__).with_name("RESULTS.md")
        with open(path, "a") as fh:
            fh.write("\n" + text)
        print(f"appended to {path}")


if __name__ == "__main__":
    main()
