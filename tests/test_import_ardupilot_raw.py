"""ArduPilot's full-rate IMU messages ACC and GYR in a DataFlash log (s28-io).

ArduPilot logs every accelerometer and gyro sample as ``ACC`` / ``GYR`` where LOG_BITMASK's
IMU_RAW bit or ``INS_RAW_LOG_OPT`` asks (libraries/AP_InertialSensor/LogStructure.h:
``"ACC", "QBQfff", "TimeUS,I,SampleUS,AccX,AccY,AccZ", "s#sooo", "F-F000"`` and ``"GYR"`` the
same with ``GyrX,GyrY,GyrZ``, ``s#sEEE``; before the ``I`` field, ArduPlane 3.8's ``ACC1``-``ACC3``
``QQfff`` ``TimeUS,SampleUS,AccX,AccY,AccZ``, as the real log tests/data/ardupilot_pymavlink/test.BIN
defines them). Before: such a log without IMU records was refused ("no IMU or MAG messages"),
and ``--source`` was for PX4 only.

The logs are written by pymavlink's own DataFlash encoder (``DataFlashWriter`` of
test_import_ardupilot, which names its sources) with those formats, units and multipliers.
"""

from __future__ import annotations

import numpy as np
from pymavlink import DFReader

from solvers.frames import normal_gravity_mps2
from station.capture import read_capture
from tests.station_run import assert_one_line_refusal, run_station
from tests.test_import_ardupilot import PARAMS, DataFlashWriter, _f32, _static_positions, calibrated_tabletop

RAW_FORMATS = {  # AP_InertialSensor/LogStructure.h LOG_STRUCTURE_FROM_INERTIALSENSOR
    "ACC": ("QBQfff", "TimeUS,I,SampleUS,AccX,AccY,AccZ", "s#sooo", "F-F000"),
    "GYR": ("QBQfff", "TimeUS,I,SampleUS,GyrX,GyrY,GyrZ", "s#sEEE", "F-F000"),
}
OLD_FORMATS = {  # ArduPlane 3.8.2 (tests/data/ardupilot_pymavlink/test.BIN's FMT records)
    f"{m}{n}": ("QQfff", f"TimeUS,SampleUS,{m[:3].title()}X,{m[:3].title()}Y,{m[:3].title()}Z", None, None)
    for m in ("ACC", "GYR")
    for n in (1, 2, 3)
}


class RawWriter(DataFlashWriter):
    """DataFlashWriter with ArduPilot's ACC/GYR (or ACC1-3/GYR1-3) formats added."""

    def __init__(self, path, formats=RAW_FORMATS):
        super().__init__(path)
        for name, (fmt, cols, units, mults) in formats.items():
            f = self.enc.add_format(DFReader.DFFormat(0, name, 0, fmt, cols))
            self.f.write(self.enc.make_format_msgbuf(f))
            self.fmt[name] = f
            if units:
                self.write("FMTU", 0, f.type, units.encode(), mults.encode())


def _tabletop(seed, rate_hz):
    """Static positions at ``rate_hz`` with a known bias and matrix: (t_s, V as logged, B, M)."""
    rng = np.random.default_rng(seed)
    g = normal_gravity_mps2(47.397742, 488.0)
    true = _static_positions(rng, g, hold_s=2.0, move_s=0.5, rate=rate_hz)
    B = np.array([0.11, -0.07, 0.16])  # A = B + M V (the station's model)
    M = np.array([[1.012, 0.003, 0.0], [0.0, 0.988, -0.002], [0.0, 0.0, 1.006]])
    V = np.linalg.solve(M, (true[:, 1:4] - B).T).T + rng.normal(0, 0.03, (len(true), 3))
    return true[:, 0], V, B, M


def _write_raw_log(path, seed, *, imu=False, old=False, params=(), n_inst=2):
    """ACC at 1 kHz, GYR at 2 kHz (two sensors each), logged in bursts: TimeUS a few ms after
    SampleUS, as the logger's thread writes them. ``imu``: IMU records at 200 Hz beside them,
    their accelerometer 1 m/s^2 off so that the two sources cannot be taken for each other."""
    t_s, V, B, M = _tabletop(seed, 1000.0)
    rng = np.random.default_rng(seed + 1)
    w = RawWriter(path, OLD_FORMATS if old else RAW_FORMATS)
    for name, value in [*PARAMS.items(), *params]:
        w.param(1000, name, value)
    gyro_t = np.arange(0.0, t_s[-1], 1 / 2000.0)
    gyro = rng.normal(0, 0.004, (len(gyro_t), 3)) + [0.002, -0.001, 0.003]
    gi = 0
    for k, (t, v) in enumerate(zip(t_s, V)):
        sample_us = int(20_000 + t * 1e6)
        logged_us = sample_us + 1000 * (4 - k % 5)  # written in bursts of 5
        for inst in range(n_inst):
            acc = v + inst * 0.5
            if old:
                w.write(f"ACC{inst + 1}", logged_us, sample_us, *acc)
            else:
                w.write("ACC", logged_us, inst, sample_us, *acc)
        while gi < len(gyro_t) and gyro_t[gi] <= t:
            g_us = int(20_000 + gyro_t[gi] * 1e6)
            for inst in (0, 1):
                if old:
                    w.write(f"GYR{inst + 1}", logged_us, g_us, *gyro[gi])
                else:
                    w.write("GYR", logged_us, inst, g_us, *gyro[gi])
            gi += 1
        if imu and k % 5 == 2:  # every 5th ACC sample: 200 Hz
            w.imu(logged_us, 0, gyro[max(gi - 1, 0)], v + 1.0)
    w.close()
    return t_s, V, B, M


def test_a_log_with_acc_and_gyr_only_calibrates_and_recovers_the_truth(tmp_path):
    """No IMU records, as when only the raw messages were kept: the tabletop run's ACC[0]
    samples are the rows, timed by SampleUS, and the fit recovers the bias and matrix."""
    log = tmp_path / "raw.bin"
    t_s, V, B, M = _write_raw_log(log, 700301)
    out = tmp_path / "raw.csv"
    res = run_station("import", log, "--procedure", "accel-tabletop", "--out", out)
    assert res.returncode == 0, res.stderr
    c = read_capture(out)
    assert c.meta["corrected"] == "true" and c.meta["accel_unit"] == "m/s^2" and c.meta["gyro_unit"] == "rad/s"
    assert c.meta["sensor_device_id"] == str(PARAMS["INS_ACC_ID"]) and c.meta["sensor_instance"] == "0"
    assert abs(float(c.meta["sample_rate_hz"]) - 1000.0) < 1e-3  # SampleUS, not the bursts of TimeUS
    np.testing.assert_array_equal(c.columns["ax"], _f32(V[: c.n_rows, 0]))
    np.testing.assert_allclose(c.columns["t"], t_s[: c.n_rows] - t_s[0], atol=2e-6)
    calibrated_tabletop(log, B, M)


def test_the_second_sensor_and_the_gyro_and_the_old_names(tmp_path):
    """--instance 1 reads ACC[1]/GYR[1]; a gyro-drift capture's rows are the 2 kHz GYR samples;
    ArduPlane 3.8's ACC2/GYR2 (no I field) are the same sensor."""
    for old in (False, True):
        log = tmp_path / f"raw-{old}.bin"
        _t, V, _B, _M = _write_raw_log(log, 700302, old=old)
        out = tmp_path / f"acc1-{old}.csv"
        res = run_station("import", log, "--procedure", "accel-tabletop", "--instance", "1", "--out", out)
        assert res.returncode == 0, res.stderr
        c = read_capture(out)
        assert c.meta["sensor_instance"] == "1" and c.meta["sensor_device_id"] == str(PARAMS["INS_ACC2_ID"])
        np.testing.assert_array_equal(c.columns["ay"], _f32(V[: c.n_rows, 1] + 0.5))
        res = run_station("import", log, "--procedure", "accel-tabletop", "--instance", "4", "--out", out)
        assert_one_line_refusal(res, "--instance 4: the log has ACC instances 0, 1; GYR instances 0, 1")
        out = tmp_path / f"acc0-{old}.csv"
        res = run_station("import", log, "--procedure", "accel-tabletop", "--out", out)
        assert res.returncode == 0 and "the log has 2 IMUs (instances 0, 1): instance 0 read" in res.stderr, res.stderr
        out = tmp_path / f"gyr-{old}.csv"
        res = run_station("import", log, "--procedure", "gyro-drift", "--out", out)
        assert res.returncode == 0, res.stderr
        assert abs(float(read_capture(out).meta["sample_rate_hz"]) - 2000.0) < 1e-2


def test_imu_by_default_acc_and_gyr_when_asked(tmp_path):
    """A log with both: IMU as before (its 1 m/s^2 shift shows which was read), said that ACC/GYR
    are there; --source raw reads ACC, --source combined IMU."""
    log = tmp_path / "both.bin"
    _t, V, _B, _M = _write_raw_log(log, 700303, imu=True)
    out = tmp_path / "imu.csv"
    res = run_station("import", log, "--procedure", "accel-tabletop", "--out", out)
    assert res.returncode == 0, res.stderr
    assert "--source raw reads them" in res.stderr and res.stderr.count("\n") == 1, res.stderr
    assert abs(float(read_capture(out).meta["sample_rate_hz"]) - 200.0) < 1.0
    assert set(_f32(read_capture(out).columns["ax"])) <= set(_f32(V[:, 0] + 1.0))
    res = run_station("import", log, "--procedure", "accel-tabletop", "--source", "raw", "--out", out)
    assert res.returncode == 0, res.stderr
    c = read_capture(out)
    np.testing.assert_array_equal(c.columns["ax"], _f32(V[: c.n_rows, 0]))
    res = run_station("import", log, "--procedure", "accel-tabletop", "--source", "combined", "--out", out)
    assert res.returncode == 0, res.stderr
    assert set(_f32(read_capture(out).columns["ax"])) <= set(_f32(V[:, 0] + 1.0))


def test_source_raw_on_a_log_without_acc_gyr_is_one_line(tmp_path):
    from tests.test_import_ardupilot import write_bin

    log = tmp_path / "imu.bin"
    write_bin(log)
    out = tmp_path / "x.csv"
    res = run_station("import", log, "--procedure", "accel-tabletop", "--source", "raw", "--out", out)
    assert_one_line_refusal(res, f"{log}: --source raw: the log has no ACC or GYR records")
    assert not out.exists()


def test_the_filtered_copy_of_pre_and_post_filter_logging_is_said(tmp_path):
    """INS_RAW_LOG_OPT bit 3 (8, pre and post filter): each sensor's filtered samples are logged
    as instance + the number of sensors (two here: INS_ACC_ID, INS_ACC2_ID), so ACC[2] is
    ACC[0] filtered (AP_InertialSensor_Backend::log_accel_raw)."""
    log = tmp_path / "prepost.bin"
    _write_raw_log(log, 700304, params=[("INS_RAW_LOG_OPT", 8.0)], n_inst=4)
    for inst, said in ((0, False), (2, True)):
        out = tmp_path / f"acc{inst}.csv"
        res = run_station("import", log, "--procedure", "accel-tabletop", "--instance", inst, "--out", out)
        assert res.returncode == 0, res.stderr
        assert ("ACC[2] is the filtered copy of ACC[0]" in res.stderr) == said, res.stderr
