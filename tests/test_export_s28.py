"""ArduPilot export: the slots the firmware's own parameter list holds, and COMPASS_OFS beyond
its documented range (s28-io).

The firmware's list is tests/data/firmware_params/ardupilot_var_info.tsv (SOURCE.md there):
IMUs 1-3 in AP_InertialSensor::var_info, IMUs 4 and 5 in its subgroups ``4_``/``5_`` of
AP_InertialSensor_Params (INS4_*, INS5_*, built where INS_MAX_INSTANCES > 3); compasses 1-3
only (COMPASS_OFS, OFS2, OFS3), COMPASS_OFS* ``@Range -400 400`` mGauss while the firmware's own
calibration stores offsets below COMPASS_OFFS_MAX.

- Before: a capture of ArduPilot's IMU instance 3 (the 4th IMU, a 5-IMU board's log) was exported
  into slot 1 (INS_ACCOFFS_*, composed with the first IMU's parameters in use): another sensor's
  parameters overwritten, exit 0. ``--instance 4`` was refused for every kind.
- Before: COMPASS_OFS_X = -650 was written without a word.

The log is written by pymavlink's own DataFlash encoder (``DataFlashWriter``); the .param file
is read back by pymavlink's ``MAVParmDict.load``.
"""

from __future__ import annotations

import contextlib
import io

import numpy as np
from db_testdata import accel_result, compass_result, gyro_result, small_capture
from pymavlink import mavparm

from db import Store
from station.capture import read_capture
from tests.station_run import run_main as run
from tests.test_firmware_world import ardupilot_definitions
from tests.test_import_ardupilot import PARAMS, DataFlashWriter

XYZ = "XYZ"
FIVE_IMUS = dict(PARAMS)
for _n, _g in ((2, "INS_ACC2"), (3, "INS_ACC3")):
    FIVE_IMUS.update({f"{_g}OFFS_{a}": 0.01 * _n * (i + 1) for i, a in enumerate(XYZ)})
    FIVE_IMUS.update({f"{_g}SCAL_{a}": 1.0 + 0.002 * _n for a in XYZ})
    FIVE_IMUS[f"INS_GYR{_n}OFFS_X"] = 0.001 * _n
FIVE_IMUS.update(INS_ACC3_ID=2883844, INS_GYR3_ID=2883588)
for _n in (4, 5):  # AP_InertialSensor_Params: ACC_ID, ACCSCAL, ACCOFFS, GYR_ID, GYROFFS
    FIVE_IMUS[f"INS{_n}_ACC_ID"] = 3014916 + _n
    FIVE_IMUS[f"INS{_n}_GYR_ID"] = 3014660 + _n
    FIVE_IMUS.update({f"INS{_n}_ACCOFFS_{a}": -0.03 * _n * (i + 1) for i, a in enumerate(XYZ)})
    FIVE_IMUS.update({f"INS{_n}_ACCSCAL_{a}": 1.0 - 0.003 * _n for a in XYZ})
    FIVE_IMUS.update({f"INS{_n}_GYROFFS_{a}": 0.002 * _n * (i + 1) for i, a in enumerate(XYZ)})
for _a in XYZ:
    FIVE_IMUS.setdefault(f"INS_GYROFFS_{_a}", 0.003)
    FIVE_IMUS.setdefault(f"INS_ACCOFFS_{_a}", 0.0)
    FIVE_IMUS.setdefault(f"INS_ACCSCAL_{_a}", 1.0)
    for _n in (2, 3):
        FIVE_IMUS.setdefault(f"INS_GYR{_n}OFFS_{_a}", 0.0)


def _five_imu_log(path):
    rng = np.random.default_rng(700401)
    w = DataFlashWriter(path)
    for name, value in FIVE_IMUS.items():
        w.param(1000, name, value)
    for k in range(400):
        t = 500_000 + k * 2500
        for inst in range(5):
            w.imu(t, inst, rng.normal(0, 0.01, 3), np.array([0.1, -0.2, -9.8]) + rng.normal(0, 0.05, 3))
    w.close()


def _export_identity(capsys, tmp_path, log, kind, inst):
    """Import IMU ``inst`` for ``kind``, calibrate with the correction that changes nothing,
    export to ArduPilot: (exit, .param text, stderr)."""
    procedure = {"accel": "accel-tabletop", "gyro": "gyro-drift"}[kind]
    out = tmp_path / f"{kind}{inst}.csv"
    code, _, err = run(capsys, "import", log, "--procedure", procedure, "--instance", inst, "--out", out)
    assert code == 0, err
    meta = read_capture(out).meta
    result = accel_result(B=(0.0, 0.0, 0.0), M=np.eye(3)) if kind == "accel" else gyro_result(drift=(0.0, 0.0, 0.0))
    _, cols = small_capture(procedure=procedure)
    db = str(tmp_path / "s.db")
    with Store(db) as s:
        cid = s.save_calibration(dict(result, device=f"ap-{kind}{inst}"), meta=meta, columns=cols)
    return run(capsys, "export", cid, "--format", "ardupilot", "--db", db)


def test_imus_4_and_5_export_into_their_own_ins4_ins5_parameters(capsys, tmp_path):
    """Every name written is in the firmware's own list (not @ReadOnly) and in the log's own
    PARM list, with the value the board stored: the 4th and 5th IMU into INS4_/INS5_."""
    log = tmp_path / "five.bin"
    _five_imu_log(log)
    defs = ardupilot_definitions()
    for kind in ("accel", "gyro"):
        for inst in (3, 4):
            code, text, err = _export_identity(capsys, tmp_path, log, kind, inst)
            assert code == 0, err
            path = tmp_path / f"{kind}{inst}.param"
            path.write_text(text)
            loaded = mavparm.MAVParmDict()
            with contextlib.redirect_stdout(io.StringIO()):
                assert loaded.load(str(path))
            assert loaded and all(n.startswith(f"INS{inst + 1}_") for n in loaded), (kind, inst, sorted(loaded))
            for name, value in loaded.items():
                assert name in defs and not defs[name][3], name
                assert np.float32(value) == np.float32(FIVE_IMUS[name]), (name, value, FIVE_IMUS[name])


def test_a_compass_or_imu_beyond_the_firmwares_slots_is_refused_in_one_line(capsys, tmp_path):
    """A capture of compass instance 3 (no COMPASS_OFS4) and --instance 4 for a compass: one line,
    exit 2, nothing on stdout. Before: the compass capture went into COMPASS_OFS (slot 1)."""
    db = str(tmp_path / "s.db")
    m, cols = small_capture(
        procedure="compass", mag_unit="mgauss", firmware="ardupilot", sensor_instance="3", mag_device_id="97795"
    )
    with Store(db) as s:
        cid = s.save_calibration(compass_result(device="M", soft_iron=(100.0 * np.eye(3)).tolist()), meta=m,
                                 columns=cols)  # fmt: skip
    code, text, err = run(capsys, "export", cid, "--format", "ardupilot", "--db", db)
    assert code == 2 and text == "" and err.count("\n") == 1, (text, err)
    assert "compass instance 3" in err and "compasses 1-3" in err, err
    code, text, err = run(capsys, "export", cid, "--format", "ardupilot", "--instance", "4", "--db", db)
    assert code == 2 and text == "" and err.count("\n") == 1 and "compasses 1-3" in err, (text, err)
    code, text, err = run(capsys, "export", cid, "--format", "ardupilot", "--instance", "3", "--db", db)
    assert code == 0 and "COMPASS_OFS3_X," in text, err


def test_compass_offsets_beyond_the_documented_range_are_written_and_said(capsys, tmp_path):
    """COMPASS_OFS_X = 650 mGauss: within COMPASS_OFFS_MAX (default 1800, what the firmware's own
    calibration accepts), beyond the documented @Range -400..400: written, and said on stderr and
    in the file. 399 mGauss: nothing said."""
    defs = ardupilot_definitions()
    assert (defs["COMPASS_OFS_X"][1], defs["COMPASS_OFS_X"][2]) == (-400.0, 400.0)
    db = str(tmp_path / "s.db")
    for seed, (hard_iron_uT, said) in enumerate(((-65.0, True), (-39.9, False))):  # COMPASS_OFS = -h: 650, 399 mGauss
        m, cols = small_capture(seed=seed, procedure="compass", mag_unit="uT")
        with Store(db) as s:
            cid = s.save_calibration(
                compass_result(device=f"M{hard_iron_uT}", hard_iron=(hard_iron_uT, 0.0, 0.0),
                               soft_iron=(1e3 * np.eye(3)).tolist()),
                meta=m, columns=cols,
            )  # fmt: skip
        code, text, err = run(capsys, "export", cid, "--format", "ardupilot", "--db", db)
        assert code == 0, err
        assert f"COMPASS_OFS_X,{-hard_iron_uT * 10:g}" in text, text
        assert ("COMPASS_OFS_X = 650.0 mGauss: beyond the documented @Range -400..400" in err) == said, err
        assert ("# warning: COMPASS_OFS_X" in text) == said
        assert err.count("\n") == int(said), err
