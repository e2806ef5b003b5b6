"""Per-step cost of the track FMU with and without its compiled steps in the shim (fmus.fast).

1. In FMPy (this process): the measurement scenario's turnout as a 2-wheel track FMU with the scenario's sensor
   layout, wheels creeping towards the crossing, 2000 steps of 1e-4 s; us per step without and with reading all
   sensor outputs after every step, with the compiled steps (default) and without (``XPANEL_FMU_FAST=0``).
2. In the C host of the tests (``tests/fixtures/fmi2_host.c``, no Python in the host): 4-wheel track FMUs (the
   16-sleeper plain track, the default turnout) with the wheels rolling at 2 m/s; us per step from two runs of
   300 and 10300 steps (best of 3 each: the start, ~0.7-0.9 s, varies by tens of ms), and the start (load
   Python, build the model, 300 steps).

Prints the figures (README "Using the FMUs in other FMI tools" quotes them; record them in RESULTS.md).
Run: python benchmarks/bench_fmu_fast.py
"""
from __future__ import annotations

import os
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
MEASUREMENT = ROOT / "scenarios" / "measurement" / "crossing_quarter_120.yaml"
DEFAULT = ROOT / "scenarios" / "crossing_1_12_through_120.yaml"
H = 1e-4


def fmpy_costs(out: Path) -> None:
    """Part 1: us per step in FMPy, with / without the compiled steps, with / without sensor reads."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    from fmus.build import build_track_fmu
    from orchestrator.inputs.scenario import load_scenario
    from orchestrator.inputs.sensor_layout import scenario_sensors
    from track.layout import build_layout

    sc = load_scenario(MEASUREMENT)
    sensors = scenario_sensors(sc)
    path = build_track_fmu(sc.track, 2, out, name="sensors2", sensors=sensors, speed=2.0, extrapolate=False,
                           static_wheel_load=0.5 * sc.vehicle.axle_load)
    unzipdir = extract(str(path), unzipdir=str(out / "sensors2_x"))
    md = read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    names = [s.id for s in sensors] + [s.id + "_acc" for s in sensors if s.type == "displacement"]
    sensor_vrs = [vr[n] for n in names]
    x_start = build_layout(sc.track.layout).sleepers[20].x - 0.5
    print(f"FMPy, {len(names)} sensor outputs, 2000 steps of {H:g} s (us per step over the last 1900):")
    for fast in ("1", "0"):
        os.environ["XPANEL_FMU_FAST"] = fast
        for read in (False, True):
            f = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier=md.coSimulation.modelIdentifier,
                          instanceName=f"bench_{fast}_{int(read)}")
            f.instantiate()
            f.setupExperiment(startTime=0.0)
            f.enterInitializationMode()
            f.exitInitializationMode()
            xs, zs = [vr["wheel1_x"], vr["wheel2_x"]], [vr["wheel1_z"], vr["wheel2_z"]]
            t0 = 0.0
            for k in range(2000):
                if k == 100:
                    t0 = time.perf_counter()
                x = x_start + 2.0 * k * H
                f.setReal(xs, [x, x])
                f.setReal(zs, [0.0, 0.0])
                f.doStep(k * H, H)
                if read:
                    f.getReal(sensor_vrs)
            us = (time.perf_counter() - t0) / 1900 * 1e6
            steps = f.getInteger([vr["python_steps"]])[0]
            f.terminate()
            f.freeInstance()
            print(f"  compiled steps {'on ' if fast == '1' else 'off'}, sensors {'read' if read else 'not read'}: "
                  f"{us:6.1f} us/step (python_steps {steps})")
    os.environ.pop("XPANEL_FMU_FAST", None)


def c_host_costs(out: Path) -> None:
    """Part 2: the C host's start and us per step for two track FMUs, with / without the compiled steps."""
    from fmpy import extract, read_model_description

    from fmus.build import build_track_fmu, find_c_compiler, fmi2_headers_dir
    from orchestrator.inputs.scenario import load_scenario
    from track.layout import build_layout
    from track.params import LayoutParams, TrackParams

    cc, headers = find_c_compiler(), fmi2_headers_dir()
    if cc is None or headers is None:
        print("C host: no C compiler or no FMI headers: skipped")
        return
    host = out / "fmi2_host"
    subprocess.run([cc, "-std=c99", "-O1", f"-I{headers}", "-o", str(host),
                    str(ROOT / "tests" / "fixtures" / "fmi2_host.c"), "-ldl"], check=True)
    sc = load_scenario(DEFAULT)
    cases = {"16-sleeper plain track": (TrackParams(layout=LayoutParams(type="plain", sleepers=16)), 3.0),
             "default turnout (40 sleepers)": (sc.track, build_layout(sc.track.layout).sleepers[5].x)}
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON")}   # a host without Python's settings
    print("C host (tests/fixtures/fmi2_host.c), 4 wheels at 2 m/s, one instance:")
    for i_case, (label, (params, x0)) in enumerate(cases.items()):
        path = build_track_fmu(params, 4, out, name=f"track{i_case}", speed=2.0)
        unzipdir = Path(extract(str(path), unzipdir=str(out / f"track{i_case}_x")))
        md = read_model_description(str(path))
        vr = {v.name: v.valueReference for v in md.modelVariables}
        for fast in ("1", "0"):
            walls = {}
            for n in (300, 10300):
                cmd = [str(host), str(unzipdir / "binaries" / "linux64" / "Track.so"),
                       (unzipdir / "resources").as_uri(), md.guid, repr(H), str(n), "-n", "1",
                       "-o", str(vr["wheel1_Fz"])]
                for i in range(4):
                    cmd += ["-l", f"{vr[f'wheel{i + 1}_x']}={x0 + 2.6 - 2.5 * (i // 2)}:2.0"]
                best = np.inf
                for _ in range(3):
                    t = time.perf_counter()
                    done = subprocess.run(cmd, env={**env, "XPANEL_FMU_FAST": fast}, capture_output=True, text=True)
                    best = min(best, time.perf_counter() - t)
                    if done.returncode != 0:
                        raise RuntimeError(done.stderr[-2000:])
                walls[n] = best
            print(f"  {label}, compiled steps {'on ' if fast == '1' else 'off'}: start + 300 steps {walls[300]:.2f} s, "
                  f"{(walls[10300] - walls[300]) / 10000 * 1e6:.0f} us/step")


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        fmpy_costs(Path(tmp))
        c_host_costs(Path(tmp))


if __name__ == "__main__":
    main()
