"""`station import` of ArduPilot DataFlash (.bin) and MAVLink (.tlog) logs.

No real ArduPilot log is in ../shared, so the logs here are WRITTEN BY PYMAVLINK'S OWN CODE:
the .bin with DFReader's DataFlash encoder (``DFFormat`` + ``make_format_msgbuf`` /
``make_msgbuf``, as pymavlink's ``tools/extract_batch_imu.py`` writes DataFlash files) using the
message formats, units and multipliers of ArduPilot's ``LogStructure`` (IMU ``s#EEEooo--O--zz``,
MAG ``s#GGGGGGGGG-s`` × ``C``); the .tlog with pymavlink's ``mavlogfile`` writer and its MAVLink
encoder, each message preceded by its 8-byte arrival time as ``mavlogfile`` reads it back.
"""

from __future__ import annotations

import datetime as dt
import json
import struct

import numpy as np
import pytest
from pymavlink import DFReader, mavutil

from solvers.frames import normal_gravity_mps2
from station.capture import read_capture
from station.importers.ardupilot import PARAM_PREFIXES
from tests.station_run import run_station

IMU_COLS = "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,EG,EA,T,GH,AH,GHz,AHz"
MAG_COLS = "TimeUS,I,MagX,MagY,MagZ,OfsX,OfsY,OfsZ,MOX,MOY,MOZ,Health,S"
GPS_COLS = "TimeUS,I,Status,GMS,GWk,NSats,HDop,Lat,Lng,Alt,Spd,GCrs,VZ,Yaw,U"
UNITS = {
    "s": "s",
    "#": "instance",
    "E": "rad/s",
    "o": "m/s/s",
    "O": "degC",
    "z": "Hz",
    "G": "Gauss",
    "-": "",
    "D": "deglatitude",
    "U": "deglongitude",
    "m": "m",
}
MULTS = {"-": 0.0, "0": 1.0, "C": 1e-3, "F": 1e-6, "G": 1e-7, "B": 1e-2}


class DataFlashWriter:
    """pymavlink's own DataFlash encoder (DFReader_binary's format table and message packers)."""

    def __init__(self, path, units: bool = True):
        self.enc = DFReader.DFReader_binary.__new__(DFReader.DFReader_binary)
        self.enc.formats = {0x80: DFReader.DFFormat(0x80, "FMT", 89, "BBnNZ", "Type,Length,Name,Format,Columns")}
        self.f = open(path, "wb")  # noqa: SIM115 - closed by close(), like a writer object
        self.fmt = {}
        for name, fmt, cols in (
            ("UNIT", "QbZ", "TimeUS,Id,Label"),
            ("MULT", "Qbd", "TimeUS,Id,Mult"),
            ("FMTU", "QBNN", "TimeUS,FmtType,UnitIds,MultIds"),
            ("PARM", "QNff", "TimeUS,Name,Value,Default"),
            ("IMU", "QBffffffIIfBBHH", IMU_COLS),
            ("MAG", "QBhhhhhhhhhBI", MAG_COLS),
            ("GPS", "QBBIHBcLLeffffB", GPS_COLS),
        ):
            f = self.enc.add_format(DFReader.DFFormat(0, name, 0, fmt, cols))
            self.f.write(self.enc.make_format_msgbuf(f))
            self.fmt[name] = f
        if units:
            for k, v in UNITS.items():
                self.write("UNIT", 0, ord(k), v.encode())
            for k, v in MULTS.items():
                self.write("MULT", 0, ord(k), v)
            for name, u, m in (
                ("IMU", "s#EEEooo--O--zz", "F-000000-----00"),
                ("MAG", "s#GGGGGGGGG-s", "F-CCCCCCCCC-F"),
            ):
                self.write("FMTU", 0, self.fmt[name].type, u.encode(), m.encode())

    def write(self, name, *values):
        self.f.write(self.enc.make_msgbuf(self.fmt[name], values))

    def param(self, t_us, name, value):
        self.write("PARM", t_us, name.encode(), value, value)

    def imu(self, t_us, inst, gyro, acc, temp=35.0):
        self.write("IMU", t_us, inst, *gyro, *acc, 0, 0, temp, 1, 1, 1000, 1000)

    def mag(self, t_us, inst, m_mgauss, ofs_mgauss=(10, -20, 30)):
        self.write("MAG", t_us, inst, *m_mgauss, *ofs_mgauss, 0, 0, 0, 1, t_us)

    def gps(self, t_us, lat_deg, lon_deg, alt_m):
        """GPS week 2300, 3000 ms into it, 3-D fix; scaled fields as stored: 'c' ×100, 'L' ×1e7, 'e' ×100."""
        self.write(
            "GPS",
            t_us,
            0,
            3,
            3000,
            2300,
            12,
            80,
            round(lat_deg * 1e7),
            round(lon_deg * 1e7),
            round(alt_m * 100),
            0,
            0,
            0,
            0,
            1,
        )

    def close(self):
        self.f.close()


def _f32(x):
    return np.asarray(x, dtype=np.float32).astype(np.float64)


PARAMS = {
    "INS_ACCOFFS_X": 0.0512,
    "INS_ACCOFFS_Y": -0.1,
    "INS_ACCOFFS_Z": 0.2,
    "INS_ACCSCAL_X": 1.01,
    "INS_ACC_ID": 2753028,
    "INS_ACC2_ID": 2818564,
    "INS_GYROFFS_X": 0.003,
    "INS_GYR_ID": 2752772,
    "INS_GYR2_ID": 2818308,
    "COMPASS_OFS_X": 120.5,
    "COMPASS_DIA_X": 1.02,
    "COMPASS_ODI_X": 0.01,
    "COMPASS_DEV_ID": 97539,
    "AHRS_ORIENTATION": 0,
    "SERIAL0_BAUD": 115,
}


def write_bin(path, n=200, units=True, late_param=False, split_dump=False):
    rng = np.random.default_rng(3)
    w = DataFlashWriter(path, units=units)
    names = list(PARAMS)
    first = names[: len(names) // 3] if split_dump else names  # the rest of the dump after the data start
    for name in first:
        w.param(1000, name, PARAMS[name])
    truth = {0: [], 1: []}
    for k in range(n):
        t = 500_000 + k * 2500  # 400 Hz
        for inst in (0, 1):
            acc = np.array([0.1, -0.2, -9.8]) + rng.normal(0, 0.05, 3) + inst
            gyro = rng.normal(0, 0.01, 3)
            w.imu(t, inst, gyro, acc)
            truth[inst].append((t, *gyro, *acc))
        if k % 4 == 0:  # compass at 100 Hz, mGauss as int16
            w.mag(t + 100, 0, (int(200 + k % 7), -150, 420))
        if k == 10:  # GPS week 2300, 3 s into it, 3-D fix over Zurich
            w.gps(t, 47.397742, 8.545594, 488.0)
        if late_param and k == n // 2:
            w.param(t, "INS_ACCOFFS_X", 0.3)
        if split_dump and k == 5:
            for name in names[len(first) :]:
                w.param(t, name, PARAMS[name])
    w.close()
    return {i: np.asarray(v) for i, v in truth.items()}


def calibrated_tabletop(log, B: np.ndarray, M: np.ndarray) -> dict:
    """`station calibrate LOG --procedure accel-tabletop --json`'s result, checked against the truth
    ``A = B + M V``: B within 5σ (+1e-4), M within 0.01."""
    res = run_station("calibrate", log, "--procedure", "accel-tabletop", "--json")
    assert res.returncode == 0, res.stderr
    r = json.loads(res.stdout)
    b, sb = np.array(r["params"]["B"]), np.array(r["uncertainty"]["B"])
    assert np.all(np.abs(b - B) <= 5 * sb + 1e-4), (b, sb)
    np.testing.assert_allclose(np.array(r["params"]["M"]), M, atol=0.01)
    return r


def test_bin_round_trip_units_parameters_date_place(tmp_path):
    log = tmp_path / "00000042.BIN"
    truth = write_bin(log)
    out = tmp_path / "ap.csv"
    res = run_station("import", log, "--procedure", "accel-tabletop", "--out", out)
    assert res.returncode == 0, res.stderr
    c = read_capture(out)
    m = c.meta
    assert (m["firmware"], m["corrected"]) == ("ardupilot", "true")
    # units from the log's own FMTU/UNIT/MULT: IMU rad/s and m/s/s, MAG Gauss × 1e-3
    assert (m["accel_unit"], m["gyro_unit"], m["mag_unit"]) == (
        "m/s^2",
        "rad/s",
        "mgauss",
    )
    assert m["sensor_device_id"] == "2753028" and m["sensor_instance"] == "0"
    assert m["gyro_device_id"] == "2752772" and m["mag_device_id"] == "97539"
    for name, value in PARAMS.items():
        if name.startswith(("INS_", "COMPASS_", "AHRS_ORIENTATION")):
            assert np.float32(float(m[f"param.{name}"])) == np.float32(value), name
    assert "param.SERIAL0_BAUD" not in m  # only the sensor calibration's parameters
    # rows are instance 0's IMU samples, to the float32 bit, from the first compass sample on
    t_us, acc = truth[0][:, 0], truth[0][:, 4:7]
    first = int(np.flatnonzero(t_us >= 500_100)[0])
    last = int(np.flatnonzero(t_us <= t_us[-1])[-1])
    np.testing.assert_array_equal(c.columns["ax"], _f32(acc[first : last + 1, 0])[: c.n_rows])
    np.testing.assert_allclose(c.columns["t"], (t_us[first : first + c.n_rows] - t_us[first]) * 1e-6, atol=1e-9)
    assert abs(float(m["sample_rate_hz"]) - 400) < 1e-6
    # the 100 Hz compass is interpolated onto the 400 Hz rows; its mGauss values are whole numbers
    assert "mag linear" in m["import_align"]
    assert np.nanmin(c.columns["mx"]) >= 200 and np.nanmax(c.columns["mx"]) <= 206
    assert np.all(c.columns["mz"][np.isfinite(c.columns["mz"])] == 420)
    # GPS week 2300 + 3 s (GPS time) − 18 leap seconds, back to the first row
    gps_unix = 315964800 + 2300 * 604800 + 3.0 - 18
    t_first_row = t_us[first] * 1e-6
    t_gps = (500_000 + 10 * 2500) * 1e-6
    want = gps_unix - t_gps + t_first_row
    assert m["date"] == dt.datetime.fromtimestamp(int(want), dt.UTC).strftime("%Y-%m-%dT%H:%M:%S")
    assert abs(float(m["latitude_deg"]) - 47.397742) < 1e-6 and abs(float(m["longitude_deg"]) - 8.545594) < 1e-6


def test_bin_second_instance_and_old_logs_without_units(tmp_path):
    log = tmp_path / "two.bin"
    truth = write_bin(log, units=False)
    out = tmp_path / "imu1.csv"
    res = run_station("import", log, "--procedure", "gyro-drift", "--instance", "1", "--out", out)
    assert res.returncode == 0, res.stderr
    c = read_capture(out)
    assert c.meta["sensor_device_id"] == "2818308" and c.meta["sensor_instance"] == "1"  # INS_GYR2_ID
    assert set(c.columns["gx"]) <= set(_f32(truth[1][:, 1]))
    # no FMTU: ArduPilot's LogStructure units (IMU rad/s, m/s/s; MAG mGauss)
    assert (c.meta["gyro_unit"], c.meta["accel_unit"]) == ("rad/s", "m/s^2")
    res = run_station(
        "import",
        log,
        "--procedure",
        "gyro-drift",
        "--instance",
        "4",
        "--out",
        tmp_path / "x.csv",
    )
    assert res.returncode == 2 and "instances 0, 1" in res.stderr and not (tmp_path / "x.csv").exists()


def test_bin_parameter_changed_during_the_data_is_flagged(tmp_path):
    log = tmp_path / "late.bin"
    write_bin(log, late_param=True)
    out = tmp_path / "late.csv"
    res = run_station("import", log, "--procedure", "accel-tabletop", "--out", out)
    assert res.returncode == 0
    c = read_capture(out)
    assert np.float32(float(c.meta["param.INS_ACCOFFS_X"])) == np.float32(0.0512)  # the value at the start
    assert c.meta["params_changed"] == "INS_ACCOFFS_X" and "INS_ACCOFFS_X" in res.stderr


def test_bin_start_up_parameter_dump_written_among_the_first_samples_is_in_use(tmp_path):
    """ArduPilot writes its start-up PARM dump while the sensor data already flow: in a real
    ArduPlane 3.8.2 log (ArduPilot/pymavlink tests/test.BIN, blob a39b77e3b75adc7dac38f052011f2039115de248)
    123 of its 809 PARM records come before the first IMU record and the other 686 after it,
    each name once. Those were all flagged 'changed while the data were logged' and left out of
    param.*, so no export could compose with them; a name's first PARM is its value in use."""
    log = tmp_path / "dump.bin"
    write_bin(log, split_dump=True)
    out = tmp_path / "dump.csv"
    res = run_station("import", log, "--procedure", "accel-tabletop", "--out", out)
    assert res.returncode == 0, res.stderr
    c = read_capture(out)
    assert "params_changed" not in c.meta and "changed" not in res.stderr
    for name, value in PARAMS.items():
        if name.startswith(PARAM_PREFIXES):  # the ones the capture keeps
            assert np.float32(float(c.meta[f"param.{name}"])) == np.float32(value), name
    assert "param.INS_GYR2_ID" in c.meta and "param.COMPASS_DEV_ID" in c.meta  # from the dump's later part
    write_bin(log, split_dump=True, late_param=True)  # a change after the dump is still one
    res = run_station("import", log, "--procedure", "accel-tabletop", "--out", out)
    assert res.returncode == 0 and read_capture(out).meta["params_changed"] == "INS_ACCOFFS_X"


def _static_positions(rng, g, n_pos=12, hold_s=4.0, move_s=1.0, rate=100.0):
    """A tabletop run: 12 orientations held still, moved by hand between them."""
    dirs = [
        np.array(v, float)
        for v in (
            (0, 0, 1),
            (0, 0, -1),
            (1, 0, 0),
            (-1, 0, 0),
            (0, 1, 0),
            (0, -1, 0),
            (1, 1, 0),
            (1, 0, 1),
            (0, 1, 1),
            (-1, 1, 1),
            (1, -1, 1),
            (1, 1, -1),
        )
    ]
    rows = []
    t = 0.0
    for k, d in enumerate(dirs[:n_pos]):
        f = g * d / np.linalg.norm(d)
        for _ in range(int(hold_s * rate)):
            rows.append((t, *f))
            t += 1 / rate
        if k < n_pos - 1:
            nxt = g * dirs[k + 1] / np.linalg.norm(dirs[k + 1])
            for j in range(int(move_s * rate)):
                s = (j + 1) / (move_s * rate)
                v = (1 - s) * f + s * nxt + rng.normal(0, 2.0, 3)
                rows.append((t, *v))
                t += 1 / rate
    return np.asarray(rows)


def test_bin_calibrates_directly_and_recovers_the_truth(tmp_path):
    """Two routes, one answer, and the answer right: a simulated tabletop run with a known
    bias and scale, logged as ArduPilot IMU messages, calibrated straight from the .bin."""
    rng = np.random.default_rng(11)
    lat, alt = 47.397742, 488.0
    g = normal_gravity_mps2(lat, alt)
    true = _static_positions(rng, g)
    B = np.array([0.08, -0.12, 0.2])  # A = B + M V  (the station's model)
    M = np.array([[1.01, 0.002, 0.0], [0.0, 0.99, -0.003], [0.0, 0.0, 1.004]])
    V = np.linalg.solve(M, (true[:, 1:4] - B).T).T + rng.normal(0, 0.02, (len(true), 3))
    log = tmp_path / "tabletop.bin"
    w = DataFlashWriter(log)
    for name, value in PARAMS.items():
        w.param(1000, name, value)
    w.gps(2000, lat, 8.545594, alt)
    for (t, *_), v in zip(true, V):
        w.imu(int(10_000 + t * 1e6), 0, (0.0, 0.0, 0.0), v)
    w.close()
    r = calibrated_tabletop(log, B, M)
    out = tmp_path / "tabletop.csv"
    assert run_station("import", log, "--procedure", "accel-tabletop", "--out", out).returncode == 0
    via = json.loads(run_station("calibrate", out, "--json").stdout)
    assert via["params"] == r["params"]


# ------------------------------------------------------------------------------------------- tlog


def write_tlog(path, autopilot=3, n=100, t0=1_700_000_000.0, second_imu=False, offsets=(), lost=()):
    """A telemetry log as MAVProxy / Mission Planner keep it, written by pymavlink;
    ``offsets``: (sample index, (x, y, z) mGauss) of SENSOR_OFFSETS messages (index −1: before
    the first sample); ``lost``: sample indices the link dropped (not written)."""
    log = mavutil.mavlogfile(str(path), write=True, source_system=1, source_component=1)
    mav = log.mav

    def at(t):
        log.write(struct.pack(">Q", int(t * 1e6)))

    at(t0)
    mav.heartbeat_send(2, autopilot, 0, 0, 4)
    ints = {"INS_ACC_ID": 6, "COMPASS_DEV_ID": 6, "AHRS_ORIENTATION": 2}
    for i, (name, value) in enumerate(PARAMS.items()):
        at(t0)
        mav.param_value_send(name.encode(), float(value), ints.get(name, 9), len(PARAMS), i)

    def sensor_offsets(k, t):
        for at_k, (x, y, z) in offsets:
            if at_k == k:
                at(t)
                mav.sensor_offsets_send(x, y, z, 0.0, 0, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)

    rng = np.random.default_rng(5)
    sent = []
    sensor_offsets(-1, t0)
    for k in range(n):
        t = t0 + 0.1 + k * 0.02  # 50 Hz
        sensor_offsets(k, t)
        acc = (int(10 + rng.integers(-3, 4)), -20, -1000)  # mG: level, Z down
        gyro = (5, -6, 7)  # mrad/s
        magv = (200, -100, 400)  # mgauss
        if k in lost:
            continue
        at(t)
        mav.raw_imu_send(1_000_000 + k * 20_000, *acc, *gyro, *magv)
        if second_imu:
            at(t)
            mav.scaled_imu2_send(1000 + k * 20, 11, 12, -990, 1, 2, 3, 0, 0, 0)
        sent.append((k * 0.02, *acc, *gyro, *magv))
    log.close()
    return np.asarray(sent)


def test_tlog_round_trip_units_from_pymavlink_definitions(tmp_path):
    log = tmp_path / "flight.tlog"
    sent = write_tlog(log, second_imu=True)
    out = tmp_path / "t.csv"
    res = run_station("import", log, "--procedure", "accel-tabletop", "--out", out)
    assert res.returncode == 0, res.stderr
    c = read_capture(out)
    m = c.meta
    # RAW_IMU from ArduPilot: mG (milli-g), mrad/s, mgauss (pymavlink's fieldunits_by_name)
    assert (m["accel_unit"], m["gyro_unit"], m["mag_unit"]) == (
        "mg",
        "mrad/s",
        "mgauss",
    )
    assert (m["firmware"], m["corrected"]) == ("ardupilot", "true")
    np.testing.assert_array_equal(c.columns["ax"], sent[:, 1])
    np.testing.assert_array_equal(c.columns["mz"], sent[:, 9])
    np.testing.assert_allclose(c.columns["t"], sent[:, 0], atol=1e-9)
    assert m["date"] == "2023-11-14T22:13:20"  # the ground station's clock, t0 = 1.7e9 s
    assert m["param.INS_ACC_ID"] == "2753028" and m["sensor_device_id"] == "2753028"
    assert np.float32(float(m["param.COMPASS_OFS_X"])) == np.float32(120.5)
    # |f| ≈ 1 g in mg: the unit is right
    f = np.linalg.norm(np.column_stack([c.columns["ax"], c.columns["ay"], c.columns["az"]]), axis=1)
    assert abs(np.median(f) - 1000) < 5
    res = run_station(
        "import",
        log,
        "--procedure",
        "accel-tabletop",
        "--instance",
        "1",
        "--out",
        tmp_path / "i1.csv",
    )
    assert res.returncode == 0, res.stderr
    c1 = read_capture(tmp_path / "i1.csv")
    assert c1.meta["import_source"].startswith("SCALED_IMU2") and "mx" not in c1.columns  # no compass there
    assert np.all(c1.columns["az"] == -990)


def test_tlog_compass_offsets_learnt_while_logging_are_said(tmp_path):
    """In-flight learning (COMPASS_LEARN) shows in a telemetry log as SENSOR_OFFSETS, with no
    PARAM_VALUE sent: the import said nothing and the export composed with the start values."""
    log = tmp_path / "learn.tlog"
    write_tlog(log, offsets=[(-1, (120, -3, 7)), (10, (120, -3, 7)), (60, (95, -3, 31))])
    out = tmp_path / "c.csv"
    res = run_station("import", log, "--procedure", "compass", "--out", out)
    assert res.returncode == 0, res.stderr
    assert "COMPASS_OFS_X" in res.stderr and "COMPASS_OFS_Z" in res.stderr and "COMPASS_OFS_Y" not in res.stderr
    assert read_capture(out).meta["params_changed"] == "COMPASS_OFS_X,COMPASS_OFS_Z"
    steady = tmp_path / "steady.tlog"
    write_tlog(steady, offsets=[(-1, (120, -3, 7)), (50, (120, -3, 7))])
    res = run_station("import", steady, "--procedure", "compass", "--out", tmp_path / "s.csv")
    assert res.returncode == 0 and "changed" not in res.stderr, res.stderr
    assert "params_changed" not in read_capture(tmp_path / "s.csv").meta


def test_tlog_samples_the_link_lost_are_said(tmp_path):
    """A radio link drops packets (a real MAVProxy .tlog, EAICS flight.tlog: 18 holes in 301
    RAW_IMU samples, the longest 1.06 s at a 0.24 s period): the import said nothing. The holes
    are said in one warning: how many, how many samples, the longest and where."""
    log = tmp_path / "lossy.tlog"
    write_tlog(log, lost=set(range(20, 23)) | set(range(60, 70)) | {80})
    res = run_station("import", log, "--procedure", "gyro-drift", "--out", tmp_path / "g.csv")
    assert res.returncode == 0, res.stderr
    said = [line for line in res.stderr.splitlines() if "telemetry link lost" in line]
    assert len(said) == 1, res.stderr
    assert "3 gaps" in said[0] and "about 14 samples" in said[0] and "0.22 s at t = 1.4 s" in said[0], said
    assert len(read_capture(tmp_path / "g.csv").columns["t"]) == 86  # what arrived, all of it
    write_tlog(tmp_path / "whole.tlog")
    res = run_station("import", tmp_path / "whole.tlog", "--procedure", "gyro-drift", "--out", tmp_path / "w.csv")
    assert res.returncode == 0 and "lost" not in res.stderr, res.stderr


def test_tlog_raw_imu_from_another_autopilot_is_counts(tmp_path):
    """The MAVLink standard's RAW_IMU is raw ADC counts; only ArduPilot fills it with mG."""
    log = tmp_path / "generic.tlog"
    write_tlog(log, autopilot=0)
    out = tmp_path / "g.csv"
    assert run_station("import", log, "--procedure", "gyro-drift", "--out", out).returncode == 0
    c = read_capture(out)
    assert c.meta["accel_unit"] == "counts" and c.meta["corrected"] == "false" and "firmware" not in c.meta


@pytest.mark.parametrize(
    "suffix, content, says",
    [
        (".bin", b"\x00" * 10 + b"not a log", "no IMU, ACC/GYR, ISBH/ISBD or MAG messages"),
        (".bin", b"", "empty file"),
        (".tlog", b"garbage" * 50, "no RAW_IMU / SCALED_IMU / HIGHRES_IMU messages"),
    ],
)
def test_bad_logs_one_line_nothing_written(tmp_path, suffix, content, says):
    bad = tmp_path / f"bad{suffix}"
    bad.write_bytes(content)
    for cmd in (
        ("import", bad, "--procedure", "accel-tabletop", "--out", tmp_path / "o.csv"),
        ("calibrate", bad, "--procedure", "accel-tabletop"),
    ):
        res = run_station(*cmd)
        assert res.returncode == 2 and res.stdout == "" and "Traceback" not in res.stderr
        assert res.stderr.count("\n") == 1 and str(bad) in res.stderr and says in res.stderr, res.stderr
    assert not (tmp_path / "o.csv").exists()


def test_units_in_the_docstrings_are_pymavlinks_own():
    """The units the reader declares are the ones pymavlink's message definitions carry."""
    from station.importers.ardupilot import MAV_UNITS

    for cls in (
        mavutil.mavlink.MAVLink_raw_imu_message,
        mavutil.mavlink.MAVLink_scaled_imu2_message,
        mavutil.mavlink.MAVLink_highres_imu_message,
    ):
        u = cls.fieldunits_by_name
        for kind, field in (("accel", "xacc"), ("gyro", "xgyro"), ("mag", "xmag")):
            assert (kind, u[field]) in MAV_UNITS


def test_tlog_from_px4_highres_imu_and_bytewise_parameters(tmp_path):
    """PX4 streams HIGHRES_IMU (m/s², rad/s, gauss, already calibrated) and sends integer
    parameters byte-wise inside PARAM_VALUE's float (MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE)."""
    log_path = tmp_path / "px4.tlog"
    log = mavutil.mavlogfile(str(log_path), write=True, source_system=1, source_component=1)
    t0 = 1_710_773_350.0

    def at(t):
        log.write(struct.pack(">Q", int(t * 1e6)))

    at(t0)
    log.mav.heartbeat_send(2, 12, 0, 0, 4)  # MAV_AUTOPILOT_PX4
    as_float = struct.unpack("<f", struct.pack("<i", 2424842))[0]
    at(t0)
    log.mav.param_value_send(b"CAL_ACC0_ID", as_float, 6, 2, 0)  # MAV_PARAM_TYPE_INT32
    at(t0)
    log.mav.param_value_send(b"CAL_ACC0_XOFF", 0.15803528, 9, 2, 1)
    for k in range(40):
        at(t0 + k * 0.004)
        log.mav.highres_imu_send(
            5_000_000 + k * 4000,
            0.02,
            -0.01,
            -9.79,
            0.001,
            -0.002,
            0.003,
            0.21,
            0.01,
            0.43,
            1013.0,
            0.0,
            100.0,
            40.5,
            0x1FFF,
        )
    log.close()
    out = tmp_path / "px4.csv"
    res = run_station("import", log_path, "--procedure", "accel-tabletop", "--out", out)
    assert res.returncode == 0, res.stderr
    c = read_capture(out)
    m = c.meta
    assert (m["firmware"], m["corrected"]) == ("px4", "true")
    assert (m["accel_unit"], m["gyro_unit"], m["mag_unit"]) == (
        "m/s^2",
        "rad/s",
        "gauss",
    )
    assert m["param.CAL_ACC0_ID"] == "2424842"  # decoded byte-wise, not 3.4e-39
    assert np.float32(float(m["param.CAL_ACC0_XOFF"])) == np.float32(0.15803528)
    assert np.all(c.columns["az"] == np.float32(-9.79)) and np.all(c.columns["temp_c"] == 40.5)
    assert abs(float(m["sample_rate_hz"]) - 250) < 1e-6


def test_tlog_with_every_message_twice_keeps_each_sample_once(tmp_path):
    """A ground station fed by two links logs each message twice (same stamp, same values)."""
    once, twice = tmp_path / "once.tlog", tmp_path / "twice.tlog"
    write_tlog(once)
    data = once.read_bytes()
    # every record (8-byte stamp + MAVLink v1 frame: 6-byte header, payload, 2-byte CRC) written twice
    out, i = bytearray(), 0
    while i < len(data):
        n = 8 + 6 + data[i + 9] + 2
        out += data[i : i + n] * 2
        i += n
    twice.write_bytes(bytes(out))
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    assert run_station("import", once, "--procedure", "gyro-drift", "--out", a).returncode == 0
    res = run_station("import", twice, "--procedure", "gyro-drift", "--out", b)
    assert res.returncode == 0 and "100 repeated IMU messages" in res.stderr
    assert read_capture(a) == read_capture(b)  # metadata and every column
    np.testing.assert_array_equal(read_capture(a).columns["gx"], read_capture(b).columns["gx"])


@pytest.mark.parametrize("saved", [True, False], ids=["in-flight, PARM logged", "internal, no PARM"])
def test_bin_compass_offsets_learnt_during_the_data_are_flagged(tmp_path, saved):
    """ArduPilot's compass learning changes the offsets while the data run: COMPASS_LEARN = 3
    (Compass_learn.cpp: mag_cal_fixed_yaw once the GSF yaw converges, saved, logged as PARM by
    GCS::send_parameter_value, then COMPASS_LEARN set to 0), or the older internal learning (1),
    which changes them with no PARM until disarm. Every MAG record carries the offsets its sample
    was corrected with (OfsX..OfsZ, compass.get_offsets). A log whose offsets change only in MAG
    imported as if one set of COMPASS_OFS corrected it all, and nothing said so. Now both are
    params_changed, in one warning line with the change, its time and COMPASS_LEARN."""
    log = tmp_path / "learn.bin"
    w = DataFlashWriter(log)
    params = dict(PARAMS, COMPASS_OFS_Y=-20.0, COMPASS_OFS_Z=30.0, COMPASS_LEARN=3 if saved else 1)
    params["COMPASS_OFS_X"] = 10.0
    for name, value in params.items():
        w.param(1000, name, value)
    for k in range(400):
        t = 500_000 + k * 10_000  # 100 Hz, 4 s
        ofs = (10, -20, 30) if k < 250 else (-35, 12, 30)  # learnt at 2.5 s
        if saved and k == 250:
            for a, v in zip("XYZ", ofs):
                w.param(t, f"COMPASS_OFS_{a}", float(v))
            w.param(t, "COMPASS_LEARN", 0.0)
        w.imu(t, 0, (0.0, 0.0, 0.0), (0.0, 0.0, -9.8))
        w.mag(t + 100, 0, (200, -150, 420), ofs)
    w.close()
    out = tmp_path / "learn.csv"
    res = run_station("import", log, "--procedure", "compass", "--out", out)
    assert res.returncode == 0, res.stderr
    meta = read_capture(out).meta
    changed = set(meta["params_changed"].split(","))
    assert {"COMPASS_OFS_X", "COMPASS_OFS_Y", "COMPASS_OFS_Z"} <= changed
    assert float(meta["param.COMPASS_OFS_X"]) == 10.0  # the value at the start
    lines = [x for x in res.stderr.splitlines() if "changed while the data were logged" in x]
    assert len(lines) == 1, res.stderr
    assert "MAG[0] offsets 10,-20,30 -> -35,12,30 mGauss from 2.5 s" in lines[0]
    assert ("COMPASS_LEARN = 3: in-flight learning" if saved else "COMPASS_LEARN = 1: internal learning") in lines[0]


def test_bin_compass_offsets_unchanged_say_nothing(tmp_path):
    log = tmp_path / "steady.bin"
    write_bin(log)
    res = run_station("import", log, "--procedure", "compass", "--out", tmp_path / "s.csv")
    assert res.returncode == 0 and "changed" not in res.stderr, res.stderr
