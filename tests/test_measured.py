"""Measured sensor data: formats, checks (each bad-data case), unit handling, alignment.

Every file is generated into ``tmp_path`` by the test that reads it.
"""
from __future__ import annotations

import h5py
import numpy as np
import pytest
import scipy.io

from orchestrator.inputs.errors import UserInputError
from orchestrator.inputs.measured import (
    MAX_GAP_SAMPLES,
    MeasuredData,
    align,
    check_measured,
    check_rate,
    read_measured,
    resample,
    write_measured,
)

SENSORS = {"A1": "pressure", "A2": "pressure", "C1": "displacement", "D1": "strain", "E1": "acceleration"}
RATE = 2000.0                 # Hz, a typical field-measurement rate
DT = 1.0 / RATE
PEAK = {"pressure": 2.0e5, "displacement": 1.5e-3, "strain": 2.0e-4, "acceleration": 150.0}   # SI, plausible
SENSOR_X = {"A1": 0.0, "A2": 0.6, "C1": 1.2, "D1": 1.8, "E1": 2.4}   # m along the track
AXLES = (0.0, 2.5)            # m, one bogie
SPEED = 30.0                  # m/s
SIGMA = 5e-3                  # s, pulse width: 10 samples at RATE


def passage(t, shift=0.0, sigma=SIGMA, sensors=SENSORS):
    """A bogie passing the sensors: one Gaussian pulse per axle and sensor, delayed by ``shift`` [s]."""
    out = {}
    for sid, typ in sensors.items():
        x = np.zeros_like(t)
        for a in AXLES:
            tc = 0.1 + (SENSOR_X[sid] + a) / SPEED + shift
            x += np.exp(-0.5 * ((t - tc) / sigma) ** 2)
        out[sid] = PEAK[typ] * x
    return out


def time_base(n=801, dt=DT, t0=0.0):
    return t0 + dt * np.arange(n)   # from an integer counter, not by accumulation


def error(match):
    return pytest.raises(UserInputError, match=match)


# --------------------------------------------------------------------------------------
# Round trips
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize("suffix", [".csv", ".h5", ".hdf5", ".mat"])
def test_round_trip_each_format(tmp_path, suffix):
    """write_measured -> read_measured gives back the same times and SI signals, nothing noted."""
    t = time_base()
    sig = passage(t)
    path = write_measured(tmp_path / f"m{suffix}", t, sig)
    data = read_measured(path, SENSORS)
    # CSV time has 17 significant digits (exact double round trip), HDF5/MAT store the doubles.
    np.testing.assert_array_equal(data.t, t)
    # CSV channels have 12 significant digits: relative rounding <= 5e-12; binary formats are exact.
    rtol = 1e-11 if suffix == ".csv" else 0.0
    assert set(data.channels) == set(SENSORS)
    for sid in SENSORS:
        np.testing.assert_allclose(data.channels[sid], sig[sid], rtol=rtol, atol=0.0)
        assert data.mask[sid].all()
    assert data.notes == ()
    assert data.source == str(path)
    # the rate from the stored time base; 1e-9 relative covers the float step k*dt
    assert data.rate == pytest.approx(RATE, rel=1e-9)


@pytest.mark.parametrize("suffix", [".csv", ".h5", ".mat"])
def test_declared_units_are_converted_to_si(tmp_path, suffix):
    """Units written into the file (CSV header, HDF5 attribute, MAT struct) come back as SI, noted."""
    t = time_base()
    sig = passage(t)
    in_file = {"A1": sig["A1"] / 1e3, "C1": sig["C1"] * 1e3, "D1": sig["D1"] * 1e6, "E1": sig["E1"] / 9.80665}
    units = {"A1": "kPa", "C1": "mm", "D1": "µε", "E1": "g"}
    path = write_measured(tmp_path / f"u{suffix}", t, in_file, units=units)
    data = read_measured(path, SENSORS)
    for sid in in_file:
        # one multiplication each way: a few ulp (CSV adds its 5e-12 rounding)
        np.testing.assert_allclose(data.channels[sid], sig[sid], rtol=1e-11, atol=1e-250)   # atol: subnormal tails
        assert any(n.startswith(f"{sid}: converted from {units[sid]}") for n in data.notes)
    assert "dropped: A2" in " ".join(data.notes)


def test_mat_struct_and_v73(tmp_path):
    """A .mat holding one struct, and a MATLAB v7.3 (HDF5) file with a char units struct, both read."""
    t = time_base()
    sig = passage(t)
    v5 = tmp_path / "struct.mat"
    scipy.io.savemat(str(v5), {"meas": {"time": t, **sig}, "operator": "someone"}, oned_as="column")
    data = read_measured(v5, SENSORS)
    for sid in SENSORS:
        np.testing.assert_array_equal(data.channels[sid], sig[sid])   # doubles stored as doubles
    assert "operator" in " ".join(data.notes)

    v73 = tmp_path / "v73.mat"
    with h5py.File(v73, "w", userblock_size=512) as f:
        g = f.create_group("meas")
        g.attrs["MATLAB_class"] = np.bytes_("struct")
        for key, x in {"time": t, **sig, "C1": sig["C1"] * 1e3}.items():
            g[key] = x[None, :]          # MATLAB stores an n-by-1 column as HDF5 shape (1, n)
            g[key].attrs["MATLAB_class"] = np.bytes_("double")
        u = f.create_group("units")
        u.attrs["MATLAB_class"] = np.bytes_("struct")
        u["C1"] = np.array([[ord(c)] for c in "mm"], dtype=np.uint16)   # char arrays are UTF-16 code units
        u["C1"].attrs["MATLAB_class"] = np.bytes_("char")
    header = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created by: test HDF5 schema 1.00 ."
    with open(v73, "r+b") as fh:
        fh.write(header.ljust(116) + bytes(8) + b"\x00\x02" + b"IM")
    data = read_measured(v73, SENSORS)
    np.testing.assert_array_equal(data.t, t)
    np.testing.assert_allclose(data.channels["C1"], sig["C1"], rtol=1e-15, atol=1e-250)   # x1e3 then x1e-3: 1 ulp
    np.testing.assert_array_equal(data.channels["A1"], sig["A1"])


def test_hdf5_at_root_with_units_attribute(tmp_path):
    """Datasets at the root (no 'sensors' group), a 'units' attribute, a non-sensor dataset and a group."""
    t = time_base()
    sig = passage(t)
    path = tmp_path / "root.hdf5"
    with h5py.File(path, "w") as f:
        f["time"] = t
        f["A1"] = sig["A1"] / 1e6
        f["A1"].attrs["units"] = np.bytes_("MPa")    # bytes, as many writers store attributes
        f["temperature"] = np.full(len(t), 21.5)
        f.create_group("metadata")
    data = read_measured(path, {"A1": "pressure"})
    # /1e6 then *1e6: 1 ulp, except in the far Gaussian tails where /1e6 went subnormal (hence atol)
    np.testing.assert_allclose(data.channels["A1"], sig["A1"], rtol=1e-15, atol=1e-250)
    assert "ignored columns that are not sensors of the layout: temperature, metadata" in data.notes
    assert "A1: converted from MPa to SI (x 1e+06)" in data.notes


def test_csv_comments_unknown_columns_and_semicolons(tmp_path):
    """'#' lines, a column that is not a sensor and ';' as delimiter are read; the column is noted."""
    t = time_base(200)
    sig = passage(t, shift=-0.1)
    lines = ["# site: crossing 1:12", "time;A1;temperature"]
    lines += [f"{float(ti)!r};{float(a)!r};21.5" for ti, a in zip(t, sig["A1"])]
    lines.insert(5, "# a comment in the middle")
    path = tmp_path / "semi.csv"
    path.write_text("\n".join(lines) + "\n")
    data = read_measured(path, {"A1": "pressure"})
    np.testing.assert_array_equal(data.channels["A1"], sig["A1"])   # repr() round-trips doubles exactly
    assert "ignored columns that are not sensors of the layout: temperature" in data.notes


def test_check_measured_leaves_the_callers_arrays_alone():
    t = time_base()
    x = passage(t)["A1"] / 1e3
    x[10] = np.nan
    before = x.copy()
    data = check_measured({"time": t, "A1": x}, {"A1": "pressure"}, units={"A1": "kPa"})
    np.testing.assert_array_equal(x, before)
    assert not data.mask["A1"][10]


# --------------------------------------------------------------------------------------
# Bad data: one clear UserInputError each
# --------------------------------------------------------------------------------------
def test_unknown_suffix(tmp_path):
    path = tmp_path / "m.xlsx"
    path.write_text("x")
    with error(r"m\.xlsx: unsupported measured-data format '\.xlsx'; supported: \.csv, \.h5, \.hdf5, \.mat"):
        read_measured(path, SENSORS)


def test_missing_file(tmp_path):
    with error(r"nope\.csv: measured-data file not found"):
        read_measured(tmp_path / "nope.csv", SENSORS)


def test_missing_required_channel_lists_ids_and_close_matches(tmp_path):
    t = time_base()
    sig = passage(t)
    sig["A_2"] = sig.pop("A2")
    path = write_measured(tmp_path / "m.csv", t, sig)
    with error(r"m\.csv: required sensor channel\(s\) missing: 'A2' \(did you mean 'A_2'\?\)$"):
        read_measured(path, SENSORS, required=["A1", "A2"])
    data = read_measured(path, SENSORS)          # not required: dropped, noted
    assert "A2" not in data.channels
    assert "sensors of the layout not in the file, dropped: A2" in data.notes
    assert "ignored columns that are not sensors of the layout: A_2" in data.notes


def test_no_time_column_and_no_sensor(tmp_path):
    path = tmp_path / "m.csv"
    path.write_text("Time,A1\n0,1\n")
    with error(r"no 'time' column \(did you mean 'Time'\?\)"):
        read_measured(path, {"A1": "pressure"})
    path.write_text("time,X9\n0,1\n0.1,2\n0.2,3\n")
    with error(r"none of the sensors 'A1' is in the file \(columns: X9\)"):
        read_measured(path, {"A1": "pressure"})


def test_nan_in_time(tmp_path):
    t = time_base()
    t[4] = np.nan
    path = write_measured(tmp_path / "m.h5", t, passage(time_base()))
    with error(r"m\.h5: time: non-finite value nan at index 4"):
        read_measured(path, SENSORS)


@pytest.mark.parametrize("bad, words", [
    (lambda t: t.__setitem__(5, t[3]), r"time decreases \(time is not monotonic\) at index 5: "
                                       r"t\[4\] = 0\.002 s, t\[5\] = 0\.0015 s"),
    (lambda t: t.__setitem__(5, t[4]), r"time repeats \(duplicated time\) at index 5: t\[4\] = 0\.002 s"),
    (lambda t: t.__setitem__(slice(300, None), t[300:] + 0.3 * DT),
     r"not uniformly sampled: step 0\.00065 s at index 300 .* median step 0\.0005 s \(2000 Hz\)"),
])
def test_bad_time_base(tmp_path, bad, words):
    t = time_base()
    bad(t)
    path = write_measured(tmp_path / "m.csv", t, passage(time_base()))
    with error(words):
        read_measured(path, SENSORS)


def test_channel_recorded_at_another_rate(tmp_path):
    t = time_base()
    path = tmp_path / "m.h5"
    with h5py.File(path, "w") as f:
        f["time"] = t
        f["A1"] = passage(t)["A1"][::2]           # recorded at half the rate
    with error(r"m\.h5: channel 'A1' has 401 samples but time has 801 \(implied rates 1000 Hz vs 2000 Hz\)"):
        read_measured(path, SENSORS)


def test_check_rate():
    t = time_base()
    data = check_measured({"time": t, **passage(t)}, SENSORS, source="m.csv")
    check_rate(data, 2000.0)                      # exactly the rate: accepted
    with error(r"m\.csv: sampling rate 2000 Hz is below the required 5000 Hz"):
        check_rate(data, 5000.0)


def test_bad_value_and_bad_type(tmp_path):
    path = tmp_path / "m.csv"
    path.write_text("time,A1\n0,1e5\n0.1,oops\n0.2,2e5\n")
    with error(r"m\.csv: line 3: column 'A1': 'oops' is not a number"):
        read_measured(path, {"A1": "pressure"})
    with error(r"m\.csv: sensor 'A1' has type 'presure' \(did you mean 'pressure'\?\)"):
        read_measured(path, {"A1": "presure"})   # the layout is checked before the file is read
    t = time_base()
    x = passage(t)["A1"]
    x[7] = np.inf
    with error(r"channel 'A1': non-finite value inf at index 7"):
        check_measured({"time": t, "A1": x}, {"A1": "pressure"})


# --------------------------------------------------------------------------------------
# NaN gaps
# --------------------------------------------------------------------------------------
def test_short_nan_gaps_are_masked_and_noted(tmp_path):
    """Gaps up to MAX_GAP_SAMPLES samples are masked; empty CSV fields count as NaN."""
    t = time_base()
    sig = passage(t)
    sig["A1"][100:100 + MAX_GAP_SAMPLES] = np.nan
    sig["A1"][0] = np.nan                          # a leading gap counts too
    path = write_measured(tmp_path / "m.csv", t, sig)
    text = path.read_text().replace(f",{sig['C1'][50]:.12g},", ",,", 1)   # one empty field
    path.write_text(text)
    data = read_measured(path, SENSORS)
    expected = np.ones(len(t), bool)
    expected[100:100 + MAX_GAP_SAMPLES] = False
    expected[0] = False
    np.testing.assert_array_equal(data.mask["A1"], expected)
    assert np.isnan(data.channels["A1"][~expected]).all()
    assert not data.mask["C1"][50] and data.mask["C1"].sum() == len(t) - 1
    assert f"A1: masked {MAX_GAP_SAMPLES + 1} NaN samples in 2 gap(s) of at most {MAX_GAP_SAMPLES} samples, " \
           f"first at t = 0 s" in data.notes


def test_long_gap_and_mostly_nan_channel():
    t = time_base()
    sig = passage(t)
    sig["A2"][200:200 + MAX_GAP_SAMPLES + 1] = np.nan
    with error(r"channel 'A2': NaN gap of 6 samples \(0\.003 s\) from index 200 \(t = 0\.1 s\) "
               r"exceeds max_gap = 0\.0025 s"):
        check_measured({"time": t, **sig}, SENSORS)
    data = check_measured({"time": t, **sig}, SENSORS, max_gap=10 * DT)   # a longer max_gap masks it
    assert (~data.mask["A2"]).sum() == MAX_GAP_SAMPLES + 1
    sig["D1"][::4] = np.nan                       # 25 % NaN, each gap one sample
    with error(r"channel 'D1' is 25\.1 % NaN \(more than 20 %\)"):
        check_measured({"time": t, **sig}, SENSORS, max_gap=10 * DT)


# --------------------------------------------------------------------------------------
# Units
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize("sid, factor, words", [
    ("A1", 1e-3, r"channel 'A1' \(pressure\), the largest of its type, peaks at 200, implausible in SI units \(Pa; .* "
                 r"probably kPa or MPa"),
    ("C1", 1e3, r"channel 'C1' \(displacement\) peaks at 1\.5, implausible in SI units \(m; .* probably mm"),
    ("D1", 1e6, r"channel 'D1' \(strain\) peaks at 200, implausible in SI units \(-; .* probably µε"),
    ("E1", 1e3, r"channel 'E1' \(acceleration\) peaks at 150000, implausible in SI units \(m/s²; .* probably mm/s²"),
])
def test_implausible_magnitude_without_declared_unit(sid, factor, words):
    t = time_base()
    sig = passage(t)
    sig[sid] = sig[sid] * factor
    if sid == "A1":
        sig["A2"] = sig["A2"] * factor            # the whole pressure group in kPa
    with error(words):
        check_measured({"time": t, **sig}, SENSORS)


def test_one_unloaded_pressure_cell_is_plausible():
    """A cell under a hanging (void) sleeper reads ~0 Pa: the lower bound uses the largest pressure cell."""
    t = time_base()
    sig = passage(t)
    sig["A2"] = 50.0 * np.sin(2 * np.pi * 50 * t)   # noise only, 50 Pa
    data = check_measured({"time": t, **sig}, SENSORS)
    assert np.nanmax(np.abs(data.channels["A2"])) < 500.0


def test_unknown_or_wrong_declared_unit(tmp_path):
    t = time_base()
    sig = passage(t)
    with error(r"channel 'C1' \(displacement\): unknown unit 'furlong'; known: 'm', 'cm', 'mm', 'um'"):
        check_measured({"time": t, **sig}, SENSORS, units={"C1": "furlong"})
    with error(r"channel 'C1' \(displacement\) peaks at 1\.5 after converting from cm"):
        check_measured({"time": t, **sig, "C1": sig["C1"] * 1e5}, SENSORS, units={"C1": "cm"})
    # time declared in ms is converted too
    data = check_measured({"time": t * 1e3, **sig}, SENSORS, units={"time": "ms"})
    assert data.rate == pytest.approx(RATE, rel=1e-9)   # ms -> s: a few ulp on the step


# --------------------------------------------------------------------------------------
# Alignment and resampling
# --------------------------------------------------------------------------------------
def test_resample_is_linear_and_nan_outside():
    t_sim = np.linspace(0.0, 1.0, 11)
    out = resample(t_sim, {"a": 3.0 * t_sim - 1.0}, np.array([-0.1, 0.0, 0.25, 0.99, 1.0, 1.01]))
    # linear interpolation reproduces a linear function up to rounding (values ~1)
    np.testing.assert_allclose(out["a"][1:5], [-1.0, -0.25, 1.97, 2.0], rtol=0, atol=1e-14)
    assert np.isnan(out["a"][[0, 5]]).all()


def measured_passage(shift, t_meas, rng, noise=0.02):
    """A 'measurement': the passage delayed by ``shift``, 30 % stronger, with white noise (2 % of peak)."""
    clean = passage(t_meas, shift)
    sig = {k: 1.3 * x + noise * PEAK[SENSORS[k]] * rng.standard_normal(x.shape) for k, x in clean.items()}
    sig["A1"][300:303] = np.nan                   # a masked dropout near a pulse
    return check_measured({"time": t_meas, **sig}, SENSORS, source="synthetic")


@pytest.mark.parametrize("shift_samples", [3.37, -2.61, 0.5])
def test_align_recovers_a_subsample_shift(shift_samples):
    """Measured = simulated delayed by a non-integer number of samples, plus noise.

    The simulation runs at 10 kHz, the measurement at 2 kHz. The shift is found to
    0.1 sample: with 2 % noise, 10-sample pulses and 10 pulses over 5 channels, the
    Cramér-Rao spread of a delay estimate is ~0.02 sample (0.018 observed over 30 noise
    seeds), and the parabola's bias on a correlation peak ~14 samples wide is ~2e-4
    sample, so 0.1 sample is a > 5-sigma margin.
    """
    rng = np.random.default_rng(7)
    t_sim = np.arange(4001) * 1e-4
    sim = passage(t_sim)
    measured = measured_passage(shift_samples * DT, time_base(), rng)
    s = align(measured, t_sim, sim)
    assert abs(s - shift_samples * DT) < 0.1 * DT
    # the sign convention: the aligned simulation matches the measurement (residual = noise)
    aligned = resample(t_sim + s, sim, measured.t)
    ok = measured.mask["C1"] & np.isfinite(aligned["C1"])
    resid = measured.channels["C1"][ok] - 1.3 * aligned["C1"][ok]
    # 2 % noise plus the slope error of a <0.1-sample misalignment: below 3 % of the peak
    assert np.std(resid) < 0.03 * PEAK["displacement"]


def test_align_respects_max_shift():
    """A periodic train of pulses: the global peak is a whole period away, max_shift finds the near one.

    One channel, four pulses P = 50 ms apart; the measurement is delayed by P + 1.3 samples.
    Unrestricted, the best overlap (4 pulses) is at P + 1.3 samples; with max_shift = P/2 the
    best allowed overlap (3 pulses) is at 1.3 samples. Tolerance 0.1 sample as above (no noise here).
    """
    P = 0.05
    t = time_base()
    train = lambda tt, s: sum(np.exp(-0.5 * ((tt - 0.1 - k * P - s) / 2e-3) ** 2) for k in range(4)) * 1e5
    t_sim = np.arange(4001) * 1e-4
    sim = {"A1": train(t_sim, 0.0)}
    measured = check_measured({"time": t, "A1": train(t, P + 1.3 * DT)}, {"A1": "pressure"})
    assert abs(align(measured, t_sim, sim) - (P + 1.3 * DT)) < 0.1 * DT
    s = align(measured, t_sim, sim, max_shift=P / 2)
    assert abs(s - 1.3 * DT) < 0.1 * DT
    assert abs(align(measured, t_sim, sim, max_shift=0.5 * DT)) <= 0.5 * DT   # clipped to the window


def test_align_weights_select_channels():
    """A channel with a different delay dominates or is ignored according to its weight."""
    rng = np.random.default_rng(3)
    t_sim = np.arange(4001) * 1e-4
    sim = passage(t_sim)
    measured = measured_passage(2.2 * DT, time_base(), rng)
    chans = dict(measured.channels)
    chans["E1"] = np.roll(np.nan_to_num(chans["E1"]), 40)      # this sensor's clock is 40 samples late
    skewed = MeasuredData(measured.t, chans, measured.mask, measured.source)
    assert abs(align(skewed, t_sim, sim, weights={"E1": 0.0}) - 2.2 * DT) < 0.1 * DT   # as above
    only_e1 = {k: 0.0 for k in SENSORS if k != "E1"}
    assert abs(align(skewed, t_sim, sim, weights=only_e1) - 42.2 * DT) < 0.1 * DT
    with error(r"weight given for 'E11', which is not a channel .* \(did you mean 'E1'\?\)"):
        align(skewed, t_sim, sim, weights={"E11": 1.0})
    with error(r"no channel in common with the simulation"):
        align(skewed, t_sim, {"Z1": sim["A1"]})


def test_required_sensor_must_be_in_the_layout(tmp_path):
    path = write_measured(tmp_path / "m.csv", time_base(), passage(time_base()))
    with error(r"m\.csv: required sensor\(s\) 'B2' are not in the sensor layout"):
        read_measured(path, SENSORS, required=["A1", "B2"])
