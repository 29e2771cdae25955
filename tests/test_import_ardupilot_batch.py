"""ArduPilot's batch sampler, ISBH/ISBD, in a DataFlash log (s29-io).

ArduPilot logs blocks of raw IMU samples where ``INS_LOG_BAT_MASK`` names an IMU (AP_InertialSensor
``BatchSampler``): ``INS_LOG_BAT_CNT`` samples of one sensor at a time, the accelerometer then the
gyro of each IMU in turn, each block an ``ISBH`` header and its ``ISBD`` records of 32 samples.
libraries/AP_InertialSensor/LogStructure.h:

- ``ISBH "QHBBHHQf" TimeUS,N,type,instance,mul,smp_cnt,SampleUS,smp_rate`` (units ``s-----sz``,
  multipliers ``F-----F-``): N the block's number, type ``IMU_SENSOR_TYPE`` (accel 0, gyro 1),
  ``mul`` the int16 scale, ``smp_cnt`` the block's samples, ``SampleUS`` its first sample's time;
- ``ISBD "QHHaaa" TimeUS,N,seqno,x,y,z`` (``s--ooo``, ``F--???``): int16[32] each, samples
  ``seqno*32`` … ``seqno*32+31`` of block N.

``BatchSampler::sample`` stores ``multiplier*sample`` (truncated to int16), the sample in m/s² or
rad/s as ACC/GYR log it; the multipliers are the front end's defaults (AP_InertialSensor.cpp:
``INT16_MAX/(16*GRAVITY_MSS)`` for an accelerometer, ``INT16_MAX/radians(2000)`` for a gyro) or the
driver's (Invensense ``INT16_MAX/(26*GRAVITY_MSS)``). Before: such a log said "no IMU or MAG
messages in the DataFlash log", and ``--source`` had no way to ask for the batches.

The logs are written by pymavlink's own DataFlash encoder (``DataFlashWriter`` of
test_import_ardupilot) with those formats, units and multipliers.
"""

from __future__ import annotations

import math
import sqlite3
from types import SimpleNamespace

import numpy as np
import pytest
from pymavlink import DFReader

from solvers.frames import normal_gravity_mps2
from station.capture import read_capture
from station.importers._common import FRD
from tests.station_run import assert_one_line_refusal, run_station
from tests.test_import_ardupilot import PARAMS, DataFlashWriter, _static_positions, calibrated_tabletop

GRAVITY_MSS = 9.80665
ACCEL_MUL = int(32767 / (16 * GRAVITY_MSS))  # AP_InertialSensor::register_accel's default: 208
GYRO_MUL = int(32767 / math.radians(2000))  # register_gyro's default: 938
ISB_FORMATS = {  # LogStructure.h LOG_STRUCTURE_FROM_INERTIALSENSOR
    "ISBH": ("QHBBHHQf", "TimeUS,N,type,instance,mul,smp_cnt,SampleUS,smp_rate", "s-----sz", "F-----F-"),
    "ISBD": ("QHHaaa", "TimeUS,N,seqno,x,y,z", "s--ooo", "F--???"),
}
PER_MSG = 32  # log_ISBD: int16_t x[32], y[32], z[32]


class BatchWriter(DataFlashWriter):
    """DataFlashWriter with ArduPilot's ISBH/ISBD formats (and MULT '?' = 1, as log_Multipliers)."""

    def __init__(self, path, formats=ISB_FORMATS):
        super().__init__(path)
        self.write("MULT", 0, ord("?"), 1.0)
        for name, (fmt, cols, units, mults) in formats.items():
            f = self.enc.add_format(DFReader.DFFormat(0, name, 0, fmt, cols))
            self.f.write(self.enc.make_format_msgbuf(f))
            self.fmt[name] = f
            self.write("FMTU", 0, f.type, units.encode(), mults.encode())

    def batch(self, n, kind, inst, mul, rate_hz, sample_us, xyz, *, skip=(), headers=True, data=True):
        """One block as BatchSampler::push_data_to_log writes it: ISBH, then an ISBD of 32
        samples every 20 ms (INS_LOG_BAT_LGIN); ``xyz`` in SI, stored as int16(mul * x)
        (C's float to int conversion: toward zero). ``skip``: ISBD seqnos not written."""
        stored = np.trunc(np.asarray(xyz, dtype=np.float32) * np.float32(mul)).astype("<i2")
        t_us = int(sample_us + len(stored) * 1e6 / rate_hz)
        if headers:
            self.write("ISBH", t_us, n, kind, inst, mul, len(stored), sample_us, rate_hz)
        for seq in range(len(stored) // PER_MSG) if data else ():
            if seq not in skip:
                part = stored[seq * PER_MSG : (seq + 1) * PER_MSG]
                self.write("ISBD", t_us + 20_000 * seq, n, seq, *(part[:, a].tobytes() for a in range(3)))
        return stored.astype(np.float64) / mul  # the samples as the log gives them back


def _write_batch_log(path, seed, *, count=2048, rate_hz=1000.0, n_pos=12, hold_s=8.0, params=(), skip=(), imu_hz=None):
    """A tabletop run whose only IMU data are the batch sampler's: accel[0] then gyro[0] blocks of
    ``count`` samples at ``rate_hz``, one after the other (a block is collected once the last is
    logged: 32 samples every 20 ms). ``imu_hz``: IMU records at that rate beside them, their
    accelerometer 1 m/s^2 off so that the two sources cannot be taken for each other. Returns
    (the accel samples' times [s] and values as stored [m/s^2], B, M, the gyro samples as
    stored [rad/s], the gyro's true drift [rad/s])."""
    rng = np.random.default_rng(seed)
    g = normal_gravity_mps2(47.397742, 488.0)
    true = _static_positions(rng, g, n_pos=n_pos, hold_s=hold_s, move_s=1.0, rate=rate_hz)
    B = np.array([0.09, -0.13, 0.18])  # A = B + M V (the station's model)
    M = np.array([[1.011, 0.002, 0.0], [0.0, 0.989, -0.003], [0.0, 0.0, 1.007]])
    V = np.linalg.solve(M, (true[:, 1:4] - B).T).T + rng.normal(0, 0.03, (len(true), 3))
    drift = np.array([0.0021, -0.0013, 0.0007])  # rad/s
    w = BatchWriter(path)
    for name, value in [*PARAMS.items(), ("INS_LOG_BAT_MASK", 1), ("INS_LOG_BAT_CNT", count), *params]:
        w.param(1000, name, value)
    acc_t, acc, acc_si, gyro = [], [], [], []
    k, n, kind = 0, 0, 0
    imu_step = int(rate_hz / imu_hz) if imu_hz else 0
    gap = int(count / PER_MSG * 0.02 * rate_hz)  # the samples while a block is logged
    while k + count <= len(true):
        t0_us = int(20_000 + true[k, 0] * 1e6)
        for i in range(k, min(k + count + gap, len(true)), imu_step or len(true)) if imu_step else ():
            w.imu(int(20_000 + true[i, 0] * 1e6), 0, drift, V[i] + 1.0)  # the IMU records meanwhile
        if kind == 0:
            stored = w.batch(n, 0, 0, ACCEL_MUL, rate_hz, t0_us, V[k : k + count], skip=skip if n == 0 else ())
            acc_t.append(true[k : k + count, 0] + 0.02)
            acc.append(stored)
            acc_si.append(V[k : k + count])
        else:
            gyro.append(w.batch(n, 1, 0, GYRO_MUL, rate_hz, t0_us, drift + rng.normal(0, 0.003, (count, 3))))
        k += count + gap  # the block, then its logging time
        n, kind = n + 1, 1 - kind
    w.close()
    return SimpleNamespace(
        acc_t=np.concatenate(acc_t),  # [s]
        acc=np.concatenate(acc),  # as stored, read back [m/s^2]
        acc_si=np.concatenate(acc_si),  # as given to the sampler [m/s^2]
        B=B,
        M=M,
        gyro=np.concatenate(gyro),  # as stored, read back [rad/s]
        drift=drift,
    )


def test_batches_read_back_as_written_in_si_units(tmp_path):
    """The accelerometer's and the gyro's blocks come back as the sampler stored them, x/mul in
    m/s^2 and rad/s (within one step 1/mul of what it was given), each sample at SampleUS +
    k/smp_rate; an ISBD the logger dropped is a gap, said, not a shift of the samples after it.
    The gyro's blocks, taken between the accelerometer's, are left out of its capture, said."""
    log = tmp_path / "batches.bin"
    w = _write_batch_log(log, 700101, count=256, n_pos=2, hold_s=2.0, skip={1})
    keep = np.ones(len(w.acc), dtype=bool)
    keep[PER_MSG : 2 * PER_MSG] = False  # block 0's ISBD seqno 1, not in the log
    out = tmp_path / "acc.csv"
    res = run_station("import", log, "--procedure", "accel-tabletop", "--out", out)
    assert res.returncode == 0, res.stderr
    assert "1 ISBD record of the batches read is missing" in res.stderr, res.stderr
    assert "the gyro samples (ISBD gyro[0]) never fall near the accelerometer's" in res.stderr, res.stderr
    c = read_capture(out)
    m = c.meta
    assert (m["import_source"], m["accel_unit"], m["corrected"], m["frame"]) == ("ISBD accel[0]", "m/s^2", "true", FRD)
    assert m["sensor_device_id"] == str(PARAMS["INS_ACC_ID"]) and m["sample_rate_hz"] == "1000"
    assert "gx" not in c.columns and c.n_rows == keep.sum()
    got = np.column_stack([c.columns[a] for a in ("ax", "ay", "az")])
    np.testing.assert_array_equal(got, w.acc[keep])
    assert np.all(np.abs(got - w.acc_si[keep]) <= 1.0 / ACCEL_MUL)  # int16(mul * x): one step at most
    t = w.acc_t[keep]
    np.testing.assert_allclose(c.columns["t"], t - t[0], atol=2e-6)  # SampleUS is whole microseconds

    # a log cut short in its last block (a power loss): read up to the cut, said once, not as
    # ISBD records the logger dropped
    cut = tmp_path / "cut.bin"
    cut.write_bytes(log.read_bytes()[:-300])
    res = run_station("import", cut, "--procedure", "accel-tabletop", "--out", tmp_path / "cut.csv")
    assert res.returncode == 0 and "the log is cut short inside a record (ISBD)" in res.stderr, res.stderr
    assert "warning: 1 ISBD record of the batches read is missing" in res.stderr, res.stderr  # block 0's alone

    out = tmp_path / "gyro.csv"
    res = run_station("import", log, "--procedure", "gyro-drift", "--out", out)
    assert res.returncode == 0, res.stderr
    g = read_capture(out)
    assert g.meta["gyro_unit"] == "rad/s" and g.meta["import_source"] == "ISBD gyro[0]"
    np.testing.assert_array_equal(np.column_stack([g.columns[a] for a in ("gx", "gy", "gz")]), w.gyro)
    assert np.all(np.abs(w.gyro - np.mean(w.gyro, axis=0)) < 0.02)  # 938 steps per rad/s: the drift's scale kept


def test_a_tabletop_run_in_batches_calibrates_to_its_truth(tmp_path):
    """A log whose only IMU data are ISBH/ISBD (no IMU, no ACC/GYR): read from the batches
    without being asked, and the P1 fit of its blocks recovers the bias within its reported
    uncertainty and the matrix."""
    log = tmp_path / "tabletop.bin"
    w = _write_batch_log(log, 700102)
    r = calibrated_tabletop(log, w.B, w.M)  # B within 5 sigma, M within 0.01
    b, sb = np.array(r["params"]["B"]), np.array(r["uncertainty"]["B"])
    assert np.all(np.abs(b - w.B) <= 3 * sb), ((b - w.B) / sb, sb)
    assert r["n_positions"] >= 9, r["n_positions"]


def test_the_batches_are_read_where_asked_beside_imu_records(tmp_path):
    """A log with IMU records too is read from IMU (the EKF's samples) and says the batches are
    there; --source batch reads them; a source the log or the format lacks is one line."""
    log = tmp_path / "both.bin"
    w = _write_batch_log(log, 700103, count=256, n_pos=2, hold_s=2.0, imu_hz=50)
    res = run_station("import", log, "--procedure", "accel-tabletop", "--out", tmp_path / "imu.csv")
    assert res.returncode == 0, res.stderr
    assert "the log also has ISBH/ISBD batches of raw IMU samples: --source batch reads them" in res.stderr
    assert read_capture(tmp_path / "imu.csv").meta["import_source"].startswith("IMU[0]")
    out = tmp_path / "isb.csv"
    res = run_station("import", log, "--procedure", "accel-tabletop", "--source", "batch", "--out", out)
    assert res.returncode == 0, res.stderr
    c = read_capture(out)
    assert c.meta["import_source"] == "ISBD accel[0]" and c.n_rows == len(w.acc)
    np.testing.assert_array_equal(c.columns["az"], w.acc[:, 2])  # not the IMU's, 1 m/s^2 off
    res = run_station("import", log, "--procedure", "accel-tabletop", "--source", "raw", "--out", tmp_path / "x.csv")
    assert_one_line_refusal(res, str(log), "--source raw: the log has no ACC or GYR records")
    tlog = tmp_path / "t.tlog"
    tlog.write_bytes(b"\xfe" + bytes(40))
    res = run_station("import", tlog, "--procedure", "accel-tabletop", "--source", "batch", "--out", tmp_path / "x.csv")
    assert_one_line_refusal(res, "--source applies to PX4 logs and ArduPilot DataFlash logs only")
    res = run_station(
        "import", tmp_path / "x.ulg", "--procedure", "accel-tabletop", "--source", "batch", "--out", tmp_path / "x.csv"
    )
    assert_one_line_refusal(res, "--source batch: PX4 logs are read from auto, raw, combined")
    assert not (tmp_path / "x.csv").exists()


def _cut_in_first_isbd(path) -> None:
    """A batch log cut short inside its first ISBD record (a power loss as logging began)."""
    _write_batch_log(path, 700104, count=256, n_pos=2, hold_s=2.0)
    data = path.read_bytes()
    isbd_type = next(f.type for f in DFReader.DFReader_binary(str(path)).formats.values() if f.name == "ISBD")
    first = data.index(bytes((0xA3, 0x95, isbd_type)), data.index(b"ISBD") + 100)
    path.write_bytes(data[: first + 40])


def _cut_in_the_only_imu_record(path) -> None:
    """An IMU log cut inside its one IMU record: "cannot read the DataFlash log (ValueError: min()
    arg is an empty sequence)" before."""
    w = DataFlashWriter(path)
    for name, value in PARAMS.items():
        w.param(1000, name, value)
    w.imu(500_000, 0, (0.0, 0.0, 0.0), (0.0, 0.0, -9.8))
    w.close()
    path.write_bytes(path.read_bytes()[:-10])


def _headers_only(path) -> None:
    w = BatchWriter(path)
    for name, value in PARAMS.items():
        w.param(1000, name, value)
    for n in range(4):
        w.batch(
            n,
            n % 2,
            0,
            ACCEL_MUL if n % 2 == 0 else GYRO_MUL,
            1000.0,
            100_000 + n * 400_000,
            np.zeros((64, 3)),
            data=False,
        )
    w.close()


def _no_sensor_messages(path) -> None:
    w = DataFlashWriter(path)
    for name, value in PARAMS.items():
        w.param(1000, name, value)
    w.gps(2000, 47.397742, 8.545594, 488.0)
    w.close()


@pytest.mark.parametrize(
    ("make", "says"),
    [
        (_cut_in_first_isbd, ("1 ISBH batch header but no ISBD records", "cut short inside a record (ISBD)")),
        (
            _cut_in_the_only_imu_record,
            ("no IMU, ACC/GYR, ISBH/ISBD or MAG messages in the DataFlash log (it has no sensor records)", "(IMU)"),
        ),
        (_headers_only, ("4 ISBH batch headers but no ISBD records",)),
        (
            _no_sensor_messages,
            ("no IMU, ACC/GYR, ISBH/ISBD or MAG messages in the DataFlash log (it has GPS records)",),
        ),
    ],
)
def test_a_log_without_samples_is_one_line_and_nothing_is_written(tmp_path, make, says):
    """Each names the file, what is wrong and the messages it looked for (IMU, ACC/GYR, ISBH/ISBD,
    MAG); exit 2, no capture file, nothing in the database."""
    log = tmp_path / "bad.bin"
    make(log)
    out, db = tmp_path / "c.csv", tmp_path / "station.db"
    res = run_station("import", log, "--procedure", "accel-tabletop", "--out", out)
    assert_one_line_refusal(res, str(log), *says, "IMU, ACC/GYR, ISBH/ISBD or MAG")
    assert not out.exists()
    res = run_station("calibrate", log, "--procedure", "accel-tabletop", "--device", "quad-1", "--save", "--db", db)
    assert_one_line_refusal(res, str(log), *says)
    if db.exists():
        with sqlite3.connect(db) as conn:
            assert conn.execute("SELECT count(*) FROM captures").fetchone() == (0,)
            assert conn.execute("SELECT count(*) FROM calibrations").fetchone() == (0,)
