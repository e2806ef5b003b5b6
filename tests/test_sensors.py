"""Virtual sensors and sensor layouts (DESIGN.md §4.3; src/track/sensors.py, orchestrator/sensor_layout.py)."""
import numpy as np
import pytest

from orchestrator.inputs.errors import UserInputError
from orchestrator.inputs.scenario import bundled_scenario, load_scenario
from orchestrator.inputs.sensor_layout import layout_from_dict, load_layout, resolve
from track.model import build_track
from track.post import sleeper_pressure
from track.sensors import (Sensor, compile_sensors, displacement_from_acceleration, sensor_signals, sleeper_of,
                           sleepers_of)
from track.statics import static_equilibrium


@pytest.fixture(scope="module")
def plain():
    sc = load_scenario(bundled_scenario("plain_track.yaml"))
    model = build_track(sc.track)
    x = model.layout.sleepers[15].x + 0.3          # mid-bay load
    pm = model.rail_point("left", x)
    st = static_equilibrium(model, [(pm, -100e3)])
    return model, pm, st


@pytest.fixture(scope="module")
def turnout():
    sc = load_scenario(bundled_scenario("measurement/crossing_quarter_120.yaml"))
    return sc, build_track(sc.track)


def test_pressure_cell_interpolates_the_bushings(plain):
    """A cell at a bushing reads its pressure; between two, the linear interpolation (exact by construction
    of the sensor, checked against track.post.sleeper_pressure: tolerance round-off)."""
    model, pm, st = plain
    k = 15
    y, p = sleeper_pressure(model, k, st.q)
    mid = 0.5 * (y[2] + y[3])
    sensors = [Sensor("P0", "pressure", "A", f"sleeper_{k}", y[2]),
               Sensor("P1", "pressure", "A", f"sleeper_{k}", mid)]
    cs = compile_sensors(model, sensors)
    q = st.q[None, :]
    sig = sensor_signals(model, cs, q, np.zeros_like(q), np.zeros_like(q), 1e-4)
    assert sig["P0"][0] == pytest.approx(p[2], rel=1e-12)
    assert sig["P1"][0] == pytest.approx(0.5 * (p[2] + p[3]), rel=1e-12)


def test_displacement_reconstruction_of_an_analytic_passage():
    """w(t) = a Gaussian dip (a sleeper under a passing wheel), a = w'' analytic.

    The reconstruction must give w high-passed: compared with the same zero-phase
    Butterworth gain applied to w directly (an independent computation: scipy's
    sosfiltfilt, forward-backward, far from the record's ends) -> 1 % of the peak
    (the two differ only by sosfiltfilt's start-up transients and the FFT's periodic
    extension, both small in the middle half of a quiet-ended record).
    """
    from scipy import signal

    dt, T = 2e-4, 1.0
    t = np.arange(0, T, dt)
    tau, t0, w0 = 0.02, 0.5, -1e-3
    g = np.exp(-0.5 * ((t - t0) / tau) ** 2)
    w = w0 * g
    a = w0 * g * (((t - t0) / tau) ** 2 - 1) / tau ** 2
    x = displacement_from_acceleration(a, dt, f_c=5.0)
    sos = signal.butter(2, 5.0, btype="highpass", fs=1 / dt, output="sos")
    ref = signal.sosfiltfilt(sos, w, padtype=None)
    mid = slice(len(t) // 4, 3 * len(t) // 4)
    assert np.max(np.abs(x[mid] - ref[mid])) < 0.01 * abs(w0)


def test_default_layout_resolves_on_the_crossing(turnout):
    sc, model = turnout
    lay = load_layout(sc.sensors)
    sensors = resolve(lay, model)
    assert [s.id for s in sensors] == lay.ids
    from track.model import reference_point
    _, x_t, k_t = reference_point(model)
    a = [s for s in sensors if s.group == "A"]
    assert {s.body for s in a} == {f"sleeper_{k_t}"} and len(a) == 6
    b = {s.id: s for s in sensors if s.group == "B"}
    assert b["B1"].body == f"sleeper_{k_t - 2}" and b["B5"].body == f"sleeper_{k_t + 2}"
    e1 = next(s for s in sensors if s.id == "E1")
    assert e1.body == "crossing" and e1.coord == pytest.approx(x_t + 0.15, abs=1e-12)
    # the sleeper a sensor sits on, read back from its body's name (the reference point's index, not parsed)
    assert sleeper_of(b["B1"].body) == k_t - 2 and sleeper_of(a[0].body) == k_t and sleeper_of(e1.body) is None
    # the layout places its sleeper sensors at T-2 .. T+2 (scenarios/sensors/in2track_like.yaml)
    assert sleepers_of(sensors) == list(range(k_t - 2, k_t + 3))
    # seat:crossing is the crossing rail's seat on that sleeper
    ys = [y for s, r, y in zip(model.pads.sleeper, model.pads.rail, model.pads.y) if s == k_t and r == "crossing"]
    assert b["B3"].coord == pytest.approx(np.mean(ys), abs=1e-12)


BASE = {"sensors": [{"id": "A1", "type": "pressure", "group": "A", "sleeper": "T", "y": 0.0}]}


@pytest.mark.parametrize("change, words", [
    ({"rate": -1}, "rate: must be a positive number"),
    ({"sensor": [1]}, "did you mean 'sensors'"),
    ({"sensors": [{"id": "A1", "type": "presure", "group": "A", "sleeper": 3, "y": 0}]}, "did you mean 'pressure'"),
    ({"sensors": [{"id": "A1", "type": "pressure", "group": "A", "rail": "crossing", "x": 1.0}]},
     "a pressure cell is under a sleeper"),
    ({"sensors": [{"id": "F1", "type": "strain", "group": "F", "rail": "crossing", "x": 1.0}]}, "z"),
    ({"sensors": BASE["sensors"] * 2}, "used twice"),
    ({"weights": {"Q": 1.0}}, "no sensor is in group 'Q'"),
])
def test_layout_errors_name_the_key(change, words):
    data = {**BASE, **change}
    with pytest.raises(UserInputError, match=words):
        layout_from_dict(data, "lay.yaml")


@pytest.mark.parametrize("entry, words", [
    ({"id": "X", "type": "pressure", "group": "A", "sleeper": "T+99", "y": 0.0}, "outside 0..39"),
    ({"id": "X", "type": "displacement", "group": "B", "sleeper": "T", "y": "seat:crosing"}, "did you mean 'crossing'"),
    ({"id": "X", "type": "acceleration", "group": "E", "rail": "crossing", "x": "T+40"}, "is off crossing"),
    ({"id": "X", "type": "acceleration", "group": "E", "rail": "nose", "x": 1.0}, "no rail 'nose'"),
])
def test_layout_positions_are_checked_on_the_model(turnout, entry, words):
    _, model = turnout
    lay = layout_from_dict({"sensors": [entry]}, "lay.yaml")
    with pytest.raises(UserInputError, match=words):
        resolve(lay, model)


def test_a_sensor_between_the_two_sleepers_of_a_split_position_is_refused():
    """Where a long panel carries one sleeper per track (track.layout._bearer) there is no sleeper in
    the gap between them: a pressure cell or an accelerometer placed there is a clear error naming the
    sensor, the position and the gap; one on either sleeper compiles."""
    from track.params import LayoutParams, TrackParams
    model = build_track(TrackParams(layout=LayoutParams(type="turnout", sleepers=64, transition_sleeper=25)))
    sl = next(s for s in model.layout.sleepers if s.gap)
    mid = 0.5 * (sl.gap[0] + sl.gap[1])
    for kind in ("pressure", "acceleration"):
        with pytest.raises(ValueError, match=rf"sensor X: y = .* between the two sleepers of position {sl.index}"):
            compile_sensors(model, [Sensor("X", kind, "A", f"sleeper_{sl.index}", mid)])
    ok = [Sensor(f"P{i}", "pressure", "A", f"sleeper_{sl.index}", 0.5 * (a + b)) for i, (a, b) in enumerate(sl.pieces)]
    assert compile_sensors(model, ok).Pb.any(axis=1).all()


def test_anti_alias_filter_passes_the_band_and_stops_what_would_fold():
    """track.sensors.anti_alias against the closed form of its specification: a Butterworth low-pass of
    order n = 4 (written here, not imported) at f_c = 0.4 x the sampling rate, digital by the bilinear
    transform on the signal's grid (rate fs: an analogue frequency f maps to tan(pi f / fs), the corner
    pre-warped), run forward and backward, has the amplitude gain
    |H(f)|^2 = 1 / (1 + (tan(pi f / fs) / tan(pi f_c / fs))^(2 n)) and no phase. Sines on a 20 kHz grid
    (a model's output) for an acquisition at 2.5 kHz (f_c = 1 kHz): at 0.5, 1 and 2 f_c the gains 0.996,
    0.5 and 0.0032, and no shift of the sine. Tolerance 1e-9: the filter's start-up transients are cut
    off (the middle half of 0.4 s is compared, 100 periods of the corner in), what is left is round-off
    (measured 3e-13)."""
    from track.sensors import anti_alias

    fs, rate, n = 20000.0, 2500.0, 4
    fc = 0.4 * rate
    t = np.arange(int(0.4 * fs)) / fs
    mid = slice(t.size // 4, 3 * t.size // 4)
    for f in (0.5 * fc, fc, 2.0 * fc):
        x = np.column_stack([np.sin(2 * np.pi * f * t), np.cos(2 * np.pi * f * t)])
        y = anti_alias(t, x, rate)
        gain = 1.0 / (1.0 + (np.tan(np.pi * f / fs) / np.tan(np.pi * fc / fs)) ** (2 * n))
        assert np.max(np.abs(y[mid] - gain * x[mid])) < 1e-9, (f, gain)
    # a grid too coarse for the corner (its Nyquist at or below f_c) is left as it is
    coarse = np.arange(100) / 1500.0
    assert np.array_equal(anti_alias(coarse, np.sin(coarse), rate), np.sin(coarse))
