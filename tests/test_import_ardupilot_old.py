"""DataFlash logs written before ArduPilot 3.3 (2015): time in ``TimeMS`` (ms since boot), not
``TimeUS``, and the GPS message as ``Status,TimeMS,Week,…,T`` (GPS time of week and week, ``T``
the boot time). Real logs of that age (for instance the public flight logs of the
erlerobot/logs repository, commit 3f7d4a0, ``pxf/copter/19-4-2015/8.BIN``, ArduCopter on a
PXF board) were refused as ``cannot read the DataFlash log (KeyError: 'TimeUS')``.

The log here is written by pymavlink's own DataFlash encoder (as tests/test_import_ardupilot.py)
with the formats, column names and types exactly as that real 2015 log declares them in its
FMT records (IMU ``IffffffIIf``, MAG ``Ihhhhhhhhh``, GPS ``BIHBcLLeeEefI``, PARM ``Nf``).
"""

from __future__ import annotations

import datetime as dt

import numpy as np
from pymavlink import DFReader

from station.capture import read_capture
from tests.station_run import run_station

OLD_FORMATS = (
    ("PARM", "Nf", "Name,Value"),
    ("GPS", "BIHBcLLeeEefI", "Status,TimeMS,Week,NSats,HDop,Lat,Lng,RelAlt,Alt,Spd,GCrs,VZ,T"),
    ("IMU", "IffffffIIf", "TimeMS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,ErrG,ErrA,Temp"),
    ("MAG", "Ihhhhhhhhh", "TimeMS,MagX,MagY,MagZ,OfsX,OfsY,OfsZ,MOfsX,MOfsY,MOfsZ"),
)
WEEK, TOW_MS = 1841, 30_078_000  # GPS week 1841 (2015-04-19 is its Sunday), 08:21:18 GPS time
GPS_BOOT_MS = 64_000  # the GPS record's T: the boot time of the fix
GPS_MINUS_UTC_2015_04_S = 16  # IERS: 16 s from 2012-07-01, 17 s from 2015-07-01


def _write_old_bin(path, n=600):
    enc = DFReader.DFReader_binary.__new__(DFReader.DFReader_binary)
    enc.formats = {0x80: DFReader.DFFormat(0x80, "FMT", 89, "BBnNZ", "Type,Length,Name,Format,Columns")}
    fmt = {}
    rng = np.random.default_rng(5)
    truth = []
    with open(path, "wb") as f:
        for name, code, cols in OLD_FORMATS:
            fmt[name] = enc.add_format(DFReader.DFFormat(0, name, 0, code, cols))
            f.write(enc.make_format_msgbuf(fmt[name]))
        for name, value in (("INS_GYROFFS_X", 0.01), ("COMPASS_OFS_X", -40.0), ("AHRS_ORIENTATION", 0.0)):
            f.write(enc.make_msgbuf(fmt["PARM"], (name.encode(), value)))
        for k in range(n):
            t_ms = 60_000 + 20 * k  # 50 Hz, as those logs
            gyro = rng.normal(0, 0.01, 3)
            acc = np.array([0.2, -0.1, -9.8]) + rng.normal(0, 0.05, 3)
            f.write(enc.make_msgbuf(fmt["IMU"], (t_ms, *gyro, *acc, 0, 0, 41.5)))
            truth.append((t_ms, *gyro, *acc))
            if k % 5 == 0:  # 10 Hz compass, mGauss
                f.write(enc.make_msgbuf(fmt["MAG"], (t_ms + 3, 210, -140, 400, -40, 0, 0, 0, 0, 0)))
            if t_ms == GPS_BOOT_MS:  # 3-D fix; stored as ints: 'c' ×100, 'L' ×1e7, 'e' ×100, 'E' ×100
                lat, lon = 48.2493733, 11.6533127
                rec = (3, TOW_MS, WEEK, 9, 150, round(lat * 1e7), round(lon * 1e7), 0, 51_200, 0, 0, 0.0, GPS_BOOT_MS)
                f.write(enc.make_msgbuf(fmt["GPS"], rec))
    return np.asarray(truth)


def test_a_log_from_before_arducopter_3_3_imports_with_its_time_date_and_place(tmp_path):
    log = tmp_path / "8.BIN"
    truth = _write_old_bin(log)
    out = tmp_path / "old.csv"
    res = run_station("import", log, "--procedure", "gyro-drift", "--out", out)
    assert res.returncode == 0, res.stderr
    c = read_capture(out)
    m = c.meta
    assert (m["firmware"], m["corrected"], m["gyro_unit"], m["accel_unit"], m["mag_unit"]) == (
        "ardupilot",
        "true",
        "rad/s",
        "m/s^2",
        "mgauss",
    )
    assert float(m["sample_rate_hz"]) == 50.0
    # rows: the IMU samples from the first compass sample (3 ms after the first IMU one) on
    first = 1
    np.testing.assert_allclose(c.columns["t"], (truth[first : first + c.n_rows, 0] - truth[first, 0]) * 1e-3, atol=1e-9)
    np.testing.assert_array_equal(c.columns["gx"], truth[first : first + c.n_rows, 1].astype(np.float32))
    assert float(m["param.INS_GYROFFS_X"]) == np.float32(0.01)
    # date: GPS week and time of week, less GPS−UTC of April 2015, back from the fix's boot time
    # to the first row
    gps_unix = 315964800 + WEEK * 604800 + TOW_MS / 1000 - GPS_MINUS_UTC_2015_04_S
    want = gps_unix - GPS_BOOT_MS / 1000 + truth[first, 0] / 1000
    assert m["date"] == dt.datetime.fromtimestamp(int(want), dt.UTC).strftime("%Y-%m-%dT%H:%M:%S")
    assert m["date"].startswith("2015-04-19")
    assert abs(float(m["latitude_deg"]) - 48.2493733) < 1e-6 and abs(float(m["altitude_m"]) - 512.0) < 1e-6


def test_an_instance_the_old_log_lacks_is_refused_not_read_from_instance_0(tmp_path):
    """Logs before the IMU/MAG ``I`` field name their second and third sensors IMU2/IMU3,
    MAG2/MAG3, and a board with one IMU and one compass has no such format at all (erlerobot/logs
    commit 3f7d4a0, ``pxf/copter/27-9-2014/70.BIN``: IMU and MAG, no MAG2 in its FMT records).
    ``--instance 1`` read IMU (MAG), instance 0, as instance 1: "MAG[1]" in the capture, with the
    second sensor's device id, so the export wrote the first sensor's fit into the second slot
    (INS_ACC2OFFS, COMPASS_OFS2). Now refused in one line naming the instances the log has; a log
    with IMU2 declared but never written (``pxf/plane/4-12-2014/329.BIN``) said "no IMU or MAG
    messages in the DataFlash log" and now says the same."""
    log = tmp_path / "70.BIN"
    _write_old_bin(log, n=60)
    for procedure in ("accel-tabletop", "compass", "gyro-drift"):
        for inst in (1, 2):
            out = tmp_path / f"{procedure}-{inst}.csv"
            res = run_station("import", log, "--procedure", procedure, "--instance", inst, "--out", out)
            assert res.returncode == 2 and res.stdout == "" and not out.exists(), (procedure, inst, res)
            assert res.stderr.count("\n") == 1, res.stderr
            assert f"--instance {inst}: the log has IMU instances 0; MAG instances 0" in res.stderr, res.stderr
        res = run_station("import", log, "--procedure", procedure, "--instance", 0, "--out", tmp_path / "ok.csv")
        assert res.returncode == 0, res.stderr
