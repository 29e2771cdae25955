"""Firmware exports against the firmwares themselves: every name written is in the firmware's
parameter list, the QGroundControl file has QGC's columns, and a correction fitted to data
the board had already corrected composes with the parameters in use into the truth.

Parameter names, read in the firmwares' own sources (the @Param / PARAM_DEFINE declarations):

- ArduPilot/ardupilot, libraries/AP_InertialSensor/AP_InertialSensor.cpp,
  commit 002f23e3d574306a293450bfbdfe5abb59ea2c96 (group prefix INS_):
  GYROFFS_X/Y/Z, GYR2OFFS_*, GYR3OFFS_*, ACCSCAL_*, ACCOFFS_*, ACC2SCAL_*, ACC2OFFS_*,
  ACC3SCAL_*, ACC3OFFS_*, GYR_ID, GYR2_ID, GYR3_ID, ACC_ID, ACC2_ID, ACC3_ID.
- ArduPilot/ardupilot, libraries/AP_Compass/AP_Compass.cpp,
  commit 7e87c92e0c89f990666f6f8a452fbea70404b047 (group prefix COMPASS_):
  OFS_*, OFS2_*, OFS3_*, DIA_*, DIA2_*, DIA3_*, ODI_*, ODI2_*, ODI3_*, SCALE, SCALE2, SCALE3,
  DEV_ID, DEV_ID2, DEV_ID3, OFFS_MAX. libraries/AP_AHRS/AP_AHRS.cpp: AHRS_ORIENTATION.
- PX4/PX4-Autopilot, src/modules/sensors/sensor_params_acc0.c (commit
  033e9cee3625392e07633088a3ebeb245a9f1dd4) and its gyro/mag siblings: CAL_ACCn_ID, _PRIO,
  _{X,Y,Z}OFF, _{X,Y,Z}SCALE; and the parameter list PX4 itself stored in a real log,
  ../shared/data/px4_ulog/original/sample_logging_tagged_and_default_params.ulg (PX4 SITL,
  ver_sw cea3da71130d9b61c426dfb3feef6943b78e838e), which also holds _ROT, CAL_MAGn_{X,Y,Z}ODIAG
  and SENS_BOARD_ROT / SENS_BOARD_{X,Y,Z}_OFF.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from db_testdata import accel_result, compass_result, gyro_result, small_capture

from db import Store
from station.capture import Capture, write_capture
from tests.station_run import run_main as run

XYZ = "XYZ"
ARDUPILOT_NAMES = (
    {
        f"INS_{g}_{a}"
        for g in (
            "GYROFFS",
            "GYR2OFFS",
            "GYR3OFFS",
            "ACCSCAL",
            "ACCOFFS",
            "ACC2SCAL",
            "ACC2OFFS",
            "ACC3SCAL",
            "ACC3OFFS",
        )
        for a in XYZ
    }
    | {
        "INS_GYR_ID",
        "INS_GYR2_ID",
        "INS_GYR3_ID",
        "INS_ACC_ID",
        "INS_ACC2_ID",
        "INS_ACC3_ID",
    }
    | {f"COMPASS_{g}_{a}" for g in ("OFS", "OFS2", "OFS3", "DIA", "DIA2", "DIA3", "ODI", "ODI2", "ODI3") for a in XYZ}
    | {
        "COMPASS_SCALE",
        "COMPASS_SCALE2",
        "COMPASS_SCALE3",
        "COMPASS_DEV_ID",
        "COMPASS_DEV_ID2",
        "COMPASS_DEV_ID3",
        "COMPASS_OFFS_MAX",
        "AHRS_ORIENTATION",
    }
)
PX4_CAL = ("ID", "PRIO", "ROT", "XOFF", "YOFF", "ZOFF")  # every CAL_<sensor>n_ has these
PX4_SCALES = ("XSCALE", "YSCALE", "ZSCALE")
PX4_SOURCE_NAMES = (
    {f"CAL_ACC{i}_{s}" for i in range(4) for s in PX4_CAL + PX4_SCALES}
    | {f"CAL_GYRO{i}_{s}" for i in range(4) for s in PX4_CAL}
    | {f"CAL_MAG{i}_{s}" for i in range(4) for s in PX4_CAL + PX4_SCALES + ("XODIAG", "YODIAG", "ZODIAG")}
    | {"SENS_BOARD_ROT", "SENS_BOARD_X_OFF", "SENS_BOARD_Y_OFF", "SENS_BOARD_Z_OFF"}
)


def names_in(text: str, fmt: str) -> dict[str, float]:
    out = {}
    for line in text.splitlines():
        if line.startswith("#") or not line.strip():
            continue
        if fmt == "ardupilot":
            name, value = line.split(",")
        elif fmt == "px4":
            _, _, name, value = line.split()
        else:
            sysid, compid, name, value, typ = line.split("\t")
            assert (sysid, compid) == ("1", "1") and typ in ("6", "9")
            assert (typ == "6") == name.endswith(("_ID", "_PRIO", "_ROT"))  # INT32 vs REAL32
        out[name] = float(value)
    return out


def _saved(capsys, tmp_path, path, *opts) -> tuple[dict, str]:
    """``calibrate PATH --json --save`` into tmp_path/s.db (exit 0 asserted): its result, the database."""
    db = str(tmp_path / "s.db")
    code, out, err = run(capsys, "calibrate", path, "--json", "--save", "--db", db, *opts)
    assert code == 0, err
    return json.loads(out), db


def _save(db, result, **meta):
    m, cols = small_capture(device=result["device"], procedure=result["procedure"])
    m.update(meta)
    with Store(db) as s:
        return s.save_calibration(result, meta=m, columns=cols)


@pytest.fixture
def every_export(db):
    """(format, instance, text) for each sensor kind, format and instance."""
    accel = _save(
        db,
        accel_result(device="A", B=(0.1, -0.2, 0.3), M=[[1.01, 0, 0], [0, 0.99, 0], [0, 0, 1.0]]),
        accel_unit="m/s^2",
        sensor_device_id="1310988",
    )
    gyro = _save(db, gyro_result(device="G"), gyro_unit="rad/s", sensor_device_id="1310988")
    mag = _save(
        db,
        compass_result(
            device="M",
            hard_iron=(10.0, -5.0, 2.0),
            soft_iron=[[1e3 * w for w in r] for r in ((1.02, 0.01, 0), (0, 0.98, 0.02), (0, 0, 1.0))],
        ),
        mag_unit="uT",
        sensor_device_id="197388",
    )
    out = []
    for cid in (accel, gyro, mag):
        for fmt, instances in (
            ("ardupilot", (1, 2, 3)),
            ("px4", (0, 1, 2, 3)),
            ("qgc", (0, 1, 2, 3)),
        ):
            for inst in instances:
                out.append(
                    (
                        fmt,
                        inst,
                        cid,
                        [
                            "export",
                            cid,
                            "--format",
                            fmt,
                            "--instance",
                            inst,
                            "--db",
                            db,
                        ],
                    )
                )
    return out


def test_every_name_written_is_in_the_firmware_parameter_list(capsys, every_export):
    written = {"ardupilot": set(), "px4": set(), "qgc": set()}
    for fmt, inst, cid, argv in every_export:  # noqa: B007
        code, out, err = run(capsys, *argv)
        assert code == 0, err
        written[fmt] |= set(names_in(out, fmt))
    assert written["ardupilot"] <= ARDUPILOT_NAMES, written["ardupilot"] - ARDUPILOT_NAMES
    assert written["px4"] == written["qgc"] and written["px4"] <= PX4_SOURCE_NAMES, written["px4"] - PX4_SOURCE_NAMES
    # the gyro offsets: INS_GYROFFS_X (not INS_GYROOFFS_X, which Mission Planner would skip)
    assert {"INS_GYROFFS_X", "INS_GYR2OFFS_Y", "INS_GYR3OFFS_Z"} <= written["ardupilot"]
    assert not any("GYROOFFS" in n for n in written["ardupilot"])
    # every kind writes the slot's device id and priority for PX4
    assert {
        "CAL_ACC0_ID",
        "CAL_GYRO1_PRIO",
        "CAL_MAG3_ID",
        "CAL_MAG2_XODIAG",
    } <= written["px4"]


def test_px4_names_are_in_the_list_px4_stored_in_a_real_log(capsys, every_export, shared_data):
    pyulog = pytest.importorskip("pyulog")
    log = shared_data / "px4_ulog" / "original" / "sample_logging_tagged_and_default_params.ulg"
    in_log = set(pyulog.ULog(str(log)).initial_parameters)
    written = set()
    for fmt, inst, cid, argv in every_export:  # noqa: B007
        if fmt == "px4" and inst in (
            0,
            1,
        ):  # this SITL build has 3 IMUs and 2 magnetometers
            written |= set(names_in(run(capsys, *argv)[1], fmt))
    assert written and written <= in_log, written - in_log


def test_qgc_file_has_qgroundcontrols_columns(capsys, db):
    cid = _save(
        db,
        compass_result(
            device="M",
            hard_iron=(10.0, -5.0, 2.0),
            soft_iron=[[1e3, 0, 0], [0, 1e3, 0], [0, 0, 1e3]],
        ),
        mag_unit="uT",
        mag_device_id="197388",
        **{
            "param.CAL_MAG1_ID": "197388",
            "param.CAL_MAG1_ROT": "0",
            "param.CAL_MAG1_PRIO": "75",
        },
    )
    code, out, err = run(capsys, "export", cid, "--format", "qgc", "--vehicle", "1,1", "--db", db)
    assert code == 0, err
    rows = [line.split("\t") for line in out.splitlines() if not line.startswith("#")]
    assert "# Vehicle-Id Component-Id Name Value Type" in out
    p = {r[2]: (float(r[3]), r[4]) for r in rows}
    # the slot is found the firmware's way: the one whose CAL_MAGn_ID holds the sensor's id
    assert p["CAL_MAG1_ID"] == (197388, "6") and p["CAL_MAG1_ROT"] == (0, "6") and p["CAL_MAG1_PRIO"] == (75, "6")
    assert p["CAL_MAG1_XOFF"][0] == pytest.approx(0.1) and p["CAL_MAG1_XOFF"][1] == "9"  # 10 uT = 0.1 gauss


# --- composition with the parameters in use -------------------------------------------------

NOMINAL_V_PER_MPS2, NOMINAL_ZERO_V = (
    0.0855,
    1.65,
)  # the simulated device family's front end


def _board_corrected_capture(tmp_path, fmt: str, seed: int):
    """Simulated P1 raw volts -> driver output r [m/s^2] (nominal front end) -> the board's
    calibration in use d = (r - o_old) * s_old (the firmware's own correction) -> a capture of d
    marked corrected, with the parameters in use. Returns (path, o_true, s_true): the firmware
    parameters that map r to the truth, from the simulator's A = B + M V."""
    from solvers.simulate import simulate

    sim = simulate("accel-tabletop", seed=seed)
    V = np.column_stack([sim.columns[k] for k in ("ax", "ay", "az")])
    r = (V - NOMINAL_ZERO_V) / NOMINAL_V_PER_MPS2
    B, M = np.asarray(sim.truth["B"]), np.asarray(sim.truth["M"])
    M_r = M * NOMINAL_V_PER_MPS2  # A = B_r + M_r r
    B_r = B + M @ np.full(3, NOMINAL_ZERO_V)
    s_true = np.diag(M_r)
    o_true = -B_r / s_true  # a = (r - o) * s, diagonal part (the firmware has no cross-axis terms)
    o_old, s_old = np.array([0.21, -0.13, 0.34]), np.array([1.012, 0.985, 1.021])
    d = (r - o_old) * s_old
    cols = dict(sim.columns, ax=d[:, 0], ay=d[:, 1], az=d[:, 2])
    meta = dict(sim.meta, accel_unit="m/s^2", corrected="true", sensor_device_id="1310988")
    if fmt == "ardupilot":
        meta.update(
            firmware="ardupilot",
            **{"param.AHRS_ORIENTATION": "0"},
            **{f"param.INS_ACCOFFS_{a}": repr(float(o_old[i])) for i, a in enumerate(XYZ)},
            **{f"param.INS_ACCSCAL_{a}": repr(float(s_old[i])) for i, a in enumerate(XYZ)},
        )
    else:
        meta.update(
            firmware="px4",
            **{
                "param.CAL_ACC0_ID": "1310988",
                "param.CAL_ACC0_PRIO": "50",
                "param.CAL_ACC0_ROT": "-1",
                "param.SENS_BOARD_ROT": "0",
            },
            **{f"param.CAL_ACC0_{a}OFF": repr(float(o_old[i])) for i, a in enumerate(XYZ)},
            **{f"param.CAL_ACC0_{a}SCALE": repr(float(s_old[i])) for i, a in enumerate(XYZ)},
        )
    path = tmp_path / f"board-{fmt}.csv"
    write_capture(path, Capture(meta=meta, columns=cols, path=path))
    return path, o_true, s_true, o_old, s_old


@pytest.mark.parametrize("fmt,seed", [("ardupilot", 3), ("px4", 4)])
def test_composed_accel_parameters_reproduce_the_truth(capsys, tmp_path, fmt, seed):
    path, o_true, s_true, _, s_old = _board_corrected_capture(tmp_path, fmt, seed)
    res, db = _saved(capsys, tmp_path, path)
    code, text, err = run(capsys, "export", res["calibration_id"], "--format", fmt, "--db", db)
    assert code == 0, err
    p = names_in(text, fmt)
    off_names = [f"INS_ACCOFFS_{a}" if fmt == "ardupilot" else f"CAL_ACC0_{a}OFF" for a in XYZ]
    scale_names = [f"INS_ACCSCAL_{a}" if fmt == "ardupilot" else f"CAL_ACC0_{a}SCALE" for a in XYZ]
    o, s = np.array([p[n] for n in off_names]), np.array([p[n] for n in scale_names])
    # 1-sigma of the composed values from the fit's own (B, M) uncertainty:
    # o = o_old + off_fit / s_old, off_fit = -B_i / M_ii; s = s_old * M_ii
    B, M = np.array(res["params"]["B"]), np.diag(np.array(res["params"]["M"]))
    sB, sM = (
        np.array(res["uncertainty"]["B"]),
        np.diag(np.array(res["uncertainty"]["M"])),
    )
    sigma_o = np.hypot(sB / M, B * sM / M**2) / s_old
    sigma_s = s_old * sM
    assert np.all(np.abs(o - o_true) < 4 * sigma_o), (o - o_true, sigma_o)
    assert np.all(np.abs(s - s_true) < 4 * sigma_s), (s - s_true, sigma_s)
    # the fit alone (as absolute parameters) would be wrong by the parameters in use
    assert np.all(np.abs(-B / M - o_true) > 10 * sigma_o)
    assert "composed with the parameters in use" in text


def test_composition_refusals_are_one_line(capsys, tmp_path):
    path, *_ = _board_corrected_capture(tmp_path, "ardupilot", 3)
    from station.capture import read_capture

    cap = read_capture(path)
    db = str(tmp_path / "s.db")

    def export_with(meta, fmt="ardupilot"):
        p = tmp_path / "c.csv"
        write_capture(p, Capture(meta=meta, columns=cap.columns, path=p))
        code, out, err = run(capsys, "calibrate", p, "--json", "--save", "--db", db)
        assert code == 0, err
        return run(
            capsys,
            "export",
            json.loads(out)["calibration_id"],
            "--format",
            fmt,
            "--db",
            db,
        )

    unknown = {k: v for k, v in cap.meta.items() if not k.startswith("param.INS_ACCSCAL")}
    code, out, err = export_with(unknown)
    assert code == 2 and out == "" and err.count("\n") == 1
    assert "no param.INS_ACCSCAL_X" in err and "in use are unknown" in err
    code, out, err = export_with(cap.meta, "px4")
    assert code == 2 and out == "" and "corrected by ardupilot parameters" in err
    # yaw 45°: per-axis scales in the body frame are no per-axis scales in the sensor frame
    # (whole 90° steps compose: tests/test_firmware_rotation.py)
    code, out, err = export_with(dict(cap.meta, **{"param.AHRS_ORIENTATION": "1"}))
    assert code == 2 and out == "" and "AHRS_ORIENTATION = 1" in err and "mixes the sensor's axes" in err
    code, out, err = export_with(dict(cap.meta, **{"param.INS_ACCSCAL_X": "1.3"}))  # composed scale ~1.27
    assert code == 2 and out == "" and "INS_ACCSCAL_X" in err and "0.8..1.2" in err


def test_px4_without_a_device_id_is_refused_and_device_id_option_works(capsys, db):
    cid = _save(db, gyro_result(device="G"), gyro_unit="rad/s")
    code, out, err = run(capsys, "export", cid, "--format", "px4", "--db", db)
    assert code == 2 and out == "" and err.count("\n") == 1 and "CAL_GYRO0_ID" in err and "--device-id" in err
    code, out, err = run(capsys, "export", cid, "--format", "px4", "--device-id", "2424842", "--db", db)
    assert code == 0 and "param set CAL_GYRO0_ID 2424842" in out


@pytest.mark.parametrize("fmt", ["px4", "qgc"])
@pytest.mark.parametrize("device_id", ["99999999999999999999", "2147483648", "-2147483649"])
def test_px4_device_id_beyond_an_int32_parameter_is_refused(capsys, db, fmt, device_id):
    """CAL_*n_ID is an int32 parameter (PX4's module.yaml; QGC type 6): a --device-id beyond it
    was written as it came, a line no vehicle takes."""
    cid = _save(db, gyro_result(device="G"), gyro_unit="rad/s")
    code, out, err = run(capsys, "export", cid, "--format", fmt, "--device-id", device_id, "--db", db)
    assert code == 2 and out == "" and err.count("\n") == 1
    assert f"CAL_GYRO0_ID = {device_id}" in err and "int32" in err


@pytest.mark.parametrize("fmt", ["px4", "qgc"])
@pytest.mark.parametrize("device_id", ["-5", "-2147483648", "16777216", "2147483647"])
def test_px4_device_id_no_sensor_can_have_is_refused(capsys, db, fmt, device_id):
    """A PX4 device id is DeviceStructure {bus_type: 3, bus: 5, address: 8, devtype: 8} in a
    uint32 union (src/lib/drivers/device/Device.hpp: "small enough to fit in a float"): 1..2^24-1.
    `--device-id -5` wrote `CAL_GYRO0_ID -5` (and a priority for a UAVCAN sensor from its low
    bits), exit 0: a slot PX4 applies to no sensor, as with the id 0 refused above. A real id
    at the top of the range is written."""
    cid = _save(db, gyro_result(device="G"), gyro_unit="rad/s")
    code, out, err = run(capsys, "export", cid, "--format", fmt, "--device-id", device_id, "--db", db)
    assert code == 2 and out == "" and err.count("\n") == 1
    assert f"CAL_GYRO0_ID = {device_id}" in err and "no PX4 sensor" in err and "16777215" in err
    code, out, err = run(capsys, "export", cid, "--format", fmt, "--device-id", str((0x88 << 16) | 3), "--db", db)
    assert code == 0 and str((0x88 << 16) | 3) in out, err  # a UAVCAN magnetometer's devtype 0x88, bus type 3


def test_composed_compass_parameters_reproduce_the_truth(capsys, tmp_path):
    """Simulated P3 raw field r [uT] -> ArduPilot's correction in use d = P_old (r + o_old)
    (mGauss, AP_Compass_Backend::correct_field) -> capture of d (gauss) marked corrected ->
    calibrate -> compose. The truth in the firmware's form: OFS = -h (mGauss), DIA/ODI = the
    symmetric part of W (from mGauss to mGauss), the same |m| as the simulator's W."""
    P_old = np.array([[1.03, 0.02, -0.01], [0.02, 0.97, 0.015], [-0.01, 0.015, 1.01]])
    path, sim = _ardupilot_compass_capture(tmp_path, P_old, device_id="97539")
    res, db = _saved(capsys, tmp_path, path)
    code, text, err = run(capsys, "export", res["calibration_id"], "--format", "ardupilot", "--db", db)
    assert code == 0, err
    p = names_in(text, "ardupilot")
    ofs = np.array([p[f"COMPASS_OFS_{a}"] for a in XYZ])
    P = np.array(
        [
            [p["COMPASS_DIA_X"], p["COMPASS_ODI_X"], p["COMPASS_ODI_Y"]],
            [p["COMPASS_ODI_X"], p["COMPASS_DIA_Y"], p["COMPASS_ODI_Z"]],
            [p["COMPASS_ODI_Y"], p["COMPASS_ODI_Z"], p["COMPASS_DIA_Z"]],
        ]
    )
    h_true_mG = np.asarray(sim.truth["hard_iron"]) * 10.0
    W_true = np.asarray(sim.truth["soft_iron"]) / 100.0 / 10.0  # uT -> nT, as mGauss -> mGauss
    vals, vecs = np.linalg.eigh(W_true.T @ W_true)
    P_true = vecs @ np.diag(np.sqrt(vals)) @ vecs.T
    # 1-sigma of the offsets: the fit's hard-iron sigma (gauss -> mGauss) through the matrix in use
    sigma_ofs = np.abs(np.linalg.inv(P_old)) @ (np.asarray(res["uncertainty"]["hard_iron"]) * 1000.0)
    assert np.all(np.abs(ofs + h_true_mG) < 4 * sigma_ofs + 0.05), (
        ofs + h_true_mG,
        sigma_ofs,
    )
    # the soft-iron matrix: the fit's relative sigma of W, ~1e-3 here; 5e-3 is several times that
    assert np.abs(P - P_true).max() < 5e-3, P - P_true
    # the fit alone, as absolute parameters, would be wrong by the parameters in use
    A_alone = np.asarray(res["params"]["soft_iron"]) / 100.0 / 1000.0  # gauss -> nT, as mGauss -> mGauss
    vals, vecs = np.linalg.eigh(A_alone.T @ A_alone)
    P_alone = vecs @ np.diag(np.sqrt(vals)) @ vecs.T
    assert np.abs(P_alone - P_true).max() > 4 * 5e-3
    assert np.all(np.abs(-np.asarray(res["params"]["hard_iron"]) * 1000.0 + h_true_mG) > 4 * sigma_ofs + 0.05)
    assert "composed with the parameters in use" in text


@pytest.mark.parametrize("scale", [1.2, 2.0, 0.5])
def test_composed_compass_offsets_follow_whether_ardupilot_applies_compass_scale(capsys, tmp_path, scale):
    """ArduPilot multiplies by COMPASS_SCALE only when Compass::have_scale_factor holds it valid,
    COMPASS_MIN_SCALE_FACTOR 0.85 to COMPASS_MAX_SCALE_FACTOR 1.4 (AP_Compass.cpp,
    CompassCalibrator.h); 0 (its default) and anything else outside is no scaling. The
    composition divided the hard iron by any non-zero COMPASS_SCALE in use: with 2.0 in use (not
    applied) the new offsets missed the truth by half the fitted hard iron. Simulated as
    correct_field does: d = P_old (s (r + o_old)), s = COMPASS_SCALE where valid, else 1."""
    P_old = np.array([[1.03, 0.02, -0.01], [0.02, 0.97, 0.015], [-0.01, 0.015, 1.01]])
    applied = scale if 0.85 <= scale <= 1.4 else 1.0  # Compass::have_scale_factor
    path, sim = _ardupilot_compass_capture(tmp_path, P_old, scale=scale)
    res, db = _saved(capsys, tmp_path, path)
    code, text, err = run(capsys, "export", res["calibration_id"], "--format", "ardupilot", "--db", db)
    assert code == 0, err
    p = names_in(text, "ardupilot")
    ofs = np.array([p[f"COMPASS_OFS_{a}"] for a in XYZ])
    h_true_mG = np.asarray(sim.truth["hard_iron"]) * 10.0
    sigma_ofs = np.abs(np.linalg.inv(applied * P_old)) @ (np.asarray(res["uncertainty"]["hard_iron"]) * 1000.0)
    assert np.all(np.abs(ofs + h_true_mG) < 4 * sigma_ofs + 0.05), (ofs + h_true_mG, sigma_ofs)


def test_composed_px4_magnetometer_parameters_reproduce_the_truth(capsys, tmp_path):
    """The same for PX4: d = S_old (r - o_old) in gauss (calibration::Magnetometer::Correct,
    offsets subtracted), slot found by CAL_MAG1_ID; truth: OFF = h, SCALE/ODIAG = sym(W)."""
    from solvers.simulate import simulate

    sim = simulate("compass", seed=5)
    r_G = np.column_stack([sim.columns[k] for k in ("mx", "my", "mz")]) / 100.0  # uT -> gauss
    o_old = np.array([0.031, -0.045, 0.012])
    S_old = np.array([[0.98, 0.01, 0.02], [0.01, 1.02, -0.015], [0.02, -0.015, 1.0]])
    d_G = (r_G - o_old) @ S_old.T
    odiag = {"X": (0, 1), "Y": (0, 2), "Z": (1, 2)}
    meta = dict(
        sim.meta,
        mag_unit="gauss",
        corrected="true",
        firmware="px4",
        mag_device_id="396809",
        **{
            "param.CAL_MAG1_ID": "396809",
            "param.CAL_MAG1_PRIO": "75",
            "param.CAL_MAG1_ROT": "0",
        },
        **{"param.CAL_MAG0_ID": "197388", "param.SENS_BOARD_ROT": "0"},
        **{f"param.CAL_MAG1_{a}OFF": repr(float(o_old[i])) for i, a in enumerate(XYZ)},
        **{f"param.CAL_MAG1_{a}SCALE": repr(float(S_old[i, i])) for i, a in enumerate(XYZ)},
        **{f"param.CAL_MAG1_{a}ODIAG": repr(float(S_old[ij])) for a, ij in odiag.items()},
    )
    cols = dict(sim.columns, mx=d_G[:, 0], my=d_G[:, 1], mz=d_G[:, 2])
    path = tmp_path / "mag.csv"
    write_capture(path, Capture(meta=meta, columns=cols, path=path))
    res, db = _saved(capsys, tmp_path, path)
    code, text, err = run(capsys, "export", res["calibration_id"], "--format", "px4", "--db", db)
    assert code == 0, err
    p = names_in(text, "px4")
    assert p["CAL_MAG1_ID"] == 396809 and p["CAL_MAG1_PRIO"] == 75 and p["CAL_MAG1_ROT"] == 0
    off = np.array([p[f"CAL_MAG1_{a}OFF"] for a in XYZ])
    S = np.diag([p[f"CAL_MAG1_{a}SCALE"] for a in XYZ])
    for a, (i, j) in odiag.items():
        S[i, j] = S[j, i] = p[f"CAL_MAG1_{a}ODIAG"]
    h_true_G = np.asarray(sim.truth["hard_iron"]) / 100.0
    W_true = np.asarray(sim.truth["soft_iron"]) * 100.0 / 1e5  # uT -> nT, as gauss -> gauss
    vals, vecs = np.linalg.eigh(W_true.T @ W_true)
    S_true = vecs @ np.diag(np.sqrt(vals)) @ vecs.T
    sigma_off = np.abs(np.linalg.inv(S_old)) @ np.asarray(res["uncertainty"]["hard_iron"])  # gauss
    assert np.all(np.abs(off - h_true_G) < 4 * sigma_off + 5e-5), (
        off - h_true_G,
        sigma_off,
    )
    assert np.abs(S - S_true).max() < 5e-3, S - S_true
    # the fit alone would miss the offsets in use by far more than its sigma
    assert np.all(np.abs(np.asarray(res["params"]["hard_iron"]) - h_true_G) > 4 * sigma_off + 5e-5)


@pytest.mark.parametrize("fmt", ["px4", "qgc"])
def test_px4_device_id_zero_is_no_sensor(capsys, db, fmt):
    """PX4 takes CAL_*n_ID = 0 for a free slot and never applies it to a sensor
    (src/lib/sensor_calibration/Utilities.cpp, FindCurrentCalibrationIndex: device id 0 → -1):
    `--device-id 0` wrote `CAL_GYRO0_ID 0` and exit 0, a file the vehicle silently ignores; a
    capture whose sensor_device_id is 0 falls back to the id in use, else is refused."""
    cid = _save(db, gyro_result(device="G"), gyro_unit="rad/s")
    code, out, err = run(capsys, "export", cid, "--format", fmt, "--device-id", "0", "--db", db)
    assert code == 2 and out == "" and err.count("\n") == 1 and "free slot" in err
    cid = _save(db, gyro_result(device="H"), gyro_unit="rad/s", sensor_device_id="0")
    code, out, err = run(capsys, "export", cid, "--format", fmt, "--db", db)
    assert code == 2 and out == "" and err.count("\n") == 1 and "--device-id" in err


def test_px4_export_of_an_older_px4_log_writes_only_names_that_firmware_has(capsys, db, shared_data):
    """sample.ulg is an older PX4 (CAL_GYRO_PRIME, CAL_GYRO0_XSCALE; no CAL_*n_PRIO): its gyro
    calibrated straight from the log exported `param set CAL_GYRO0_PRIO 50`, a parameter that
    firmware does not have (the shell's `param set` fails on it, QGroundControl's load reports
    it). Every name written is now in the parameter list the log itself holds (read by pyulog)."""
    pyulog = pytest.importorskip("pyulog")
    log = shared_data / "px4_ulog" / "original" / "sample.ulg"
    in_log = set(pyulog.ULog(str(log), []).initial_parameters)
    assert "CAL_GYRO0_XOFF" in in_log and "CAL_GYRO0_PRIO" not in in_log  # the firmware as it is
    code, out, err = run(capsys, "calibrate", log, "--procedure", "gyro-drift", "--save", "--json", "--db", db)
    assert code in (0, 1), err
    if code == 1:  # a FAIL verdict on a flight log: accepted as an override, as an operator would
        code, out, err = run(
            capsys, "calibrate", log, "--procedure", "gyro-drift", "--save", "--json", "--override", "x", "--db", db
        )
    cid = json.loads(out)["calibration_id"]
    for fmt in ("px4", "qgc"):
        # two gyro slots in use and no sensor_selection in the log: which one is the operator's word
        code, out, err = run(capsys, "export", cid, "--format", fmt, "--db", db)
        assert code == 2 and "CAL_GYRO0_ID = 2162688 and CAL_GYRO1_ID = 2359296 in use" in err, err
        code, out, err = run(capsys, "export", cid, "--format", fmt, "--db", db, "--instance", "0")
        assert code == 0, err
        written = set(names_in(out, fmt))
        assert {"CAL_GYRO0_ID", "CAL_GYRO0_XOFF"} <= written and written <= in_log, written - in_log
        assert "CAL_GYRO0_PRIO not written" in out


def test_px4_magnetometer_for_a_firmware_without_odiag_writes_the_diagonal_only(capsys, tmp_path):
    """An older PX4 has CAL_MAGn_{X,Y,Z}SCALE but no ODIAG and no PRIO (sample.ulg's list):
    data it corrected with diagonal scales are exported with the names it has, the dropped
    off-diagonal said in a comment; the diagonal is the truth's."""
    from solvers.simulate import simulate

    sim = simulate("compass", seed=5)
    r_G = np.column_stack([sim.columns[k] for k in ("mx", "my", "mz")]) / 100.0  # uT -> gauss
    o_old, s_old = np.array([0.031, -0.045, 0.012]), np.array([0.98, 1.02, 1.0])
    d_G = (r_G - o_old) * s_old
    meta = dict(
        sim.meta,
        mag_unit="gauss",
        corrected="true",
        firmware="px4",
        mag_device_id="396809",
        **{"param.CAL_MAG0_ID": "396809", "param.CAL_MAG0_ROT": "-1", "param.SENS_BOARD_ROT": "0"},
        **{f"param.CAL_MAG0_{a}OFF": repr(float(o_old[i])) for i, a in enumerate(XYZ)},
        **{f"param.CAL_MAG0_{a}SCALE": repr(float(s_old[i])) for i, a in enumerate(XYZ)},
    )
    path = tmp_path / "mag.csv"
    write_capture(path, Capture(meta=meta, columns=dict(sim.columns, mx=d_G[:, 0], my=d_G[:, 1], mz=d_G[:, 2])))
    res, db = _saved(capsys, tmp_path, path)
    for fmt in ("px4", "qgc"):
        code, text, err = run(capsys, "export", res["calibration_id"], "--format", fmt, "--db", db)
        assert code == 0, err
        p = names_in(text, fmt)
        assert not [n for n in p if "ODIAG" in n or "PRIO" in n], p
        assert "CAL_MAG0_*ODIAG not written" in text and "CAL_MAG0_PRIO not written" in text
        W_true = np.asarray(sim.truth["soft_iron"]) * 100.0 / 1e5
        vals, vecs = np.linalg.eigh(W_true.T @ W_true)
        S_true = vecs @ np.diag(np.sqrt(vals)) @ vecs.T
        assert np.abs(np.array([p[f"CAL_MAG0_{a}SCALE"] for a in XYZ]) - np.diag(S_true)).max() < 5e-3


@pytest.mark.parametrize("vehicle", ["-1,999", "0,1", "256,1", "1,-1", "1,256"])
def test_qgc_vehicle_ids_outside_mavlinks_byte_are_refused(capsys, db, vehicle):
    """MAVLink's system and component ids are one byte each, system 1-255 (0 is broadcast):
    --vehicle=-1,999 wrote '-1<TAB>999<TAB>CAL_...' lines that no vehicle answers to."""
    cid = _save(db, gyro_result(device="G"), gyro_unit="rad/s")
    code, out, err = run(
        capsys, "export", cid, "--format", "qgc", "--device-id", "2424842", f"--vehicle={vehicle}", "--db", db
    )
    assert code == 2 and out == "" and err.count("\n") == 1 and f"--vehicle {vehicle!r}" in err and "1-255" in err
    code, out, err = run(
        capsys, "export", cid, "--format", "qgc", "--device-id", "2424842", "--vehicle=255,0", "--db", db
    )
    assert code == 0 and "255\t0\tCAL_GYRO0_ID" in out, err


def _ardupilot_compass_capture(tmp_path, P_old, dia_in_use=None, scale=None, device_id=None):
    """Simulated P3 raw field -> ArduPilot's correction d = P_old (s (r + o_old)) (mGauss,
    AP_Compass_Backend::correct_field) -> capture of d marked corrected, with the parameters in
    use (DIA as ``dia_in_use`` when given: the parameter values, P_old the matrix they give;
    COMPASS_SCALE ``scale`` when given, s = scale where Compass::have_scale_factor holds it
    valid, 0.85 to 1.4, else 1; the magnetometer's ``device_id`` and COMPASS_DEV_ID when given)."""
    from solvers.simulate import simulate

    sim = simulate("compass", seed=2)
    r_mG = np.column_stack([sim.columns[k] for k in ("mx", "my", "mz")]) * 10.0  # 1 uT = 10 mGauss
    o_old = np.array([-35.0, 52.0, 18.0])
    applied = scale if scale is not None and 0.85 <= scale <= 1.4 else 1.0
    d_gauss = applied * (r_mG + o_old) @ P_old.T / 1000.0
    dia = np.diag(P_old) if dia_in_use is None else dia_in_use
    in_use = {"param.AHRS_ORIENTATION": "0"} | ({} if scale is None else {"param.COMPASS_SCALE": repr(scale)})
    if device_id is not None:
        in_use |= {"mag_device_id": device_id, "param.COMPASS_DEV_ID": device_id}
    in_use |= {f"param.COMPASS_OFS_{a}": repr(float(o_old[i])) for i, a in enumerate(XYZ)}
    in_use |= {f"param.COMPASS_DIA_{a}": repr(float(dia[i])) for i, a in enumerate(XYZ)}
    in_use |= {f"param.COMPASS_ODI_{a}": repr(float(P_old[i, j])) for a, (i, j) in zip(XYZ, ((0, 1), (0, 2), (1, 2)))}
    return corrected_compass_capture(tmp_path / "mag.csv", sim, d_gauss, "ardupilot", in_use), sim


def corrected_compass_capture(path, sim, d_gauss, firmware: str, in_use: dict):
    """The simulated compass capture ``sim`` with the field the board handed over, ``d_gauss``
    (already corrected by it), marked corrected by ``firmware`` with the metadata ``in_use``
    (its parameters as param.NAME): written to ``path``, which is returned."""
    meta = dict(sim.meta, mag_unit="gauss", corrected="true", firmware=firmware, **in_use)
    cols = dict(sim.columns, mx=d_gauss[:, 0], my=d_gauss[:, 1], mz=d_gauss[:, 2])
    write_capture(path, Capture(meta=meta, columns=cols, path=path))
    return path


def test_a_partly_zero_compass_diagonal_in_use_is_a_broken_calibration_not_identity(capsys, tmp_path):
    """AP_Compass_Backend::correct_field: `if (state.diagonals.get().is_zero()) diagonals = (1,1,1)`,
    all three or nothing (read in ArduPilot/ardupilot libraries/AP_Compass/AP_Compass_Backend.cpp).
    The export read COMPASS_DIA element by element: DIA_Y = 0 beside DIA_X, DIA_Z was taken as 1
    and new parameters were composed on a matrix the firmware never used. The board really
    multiplied its y axis by 0 (only the off-diagonal terms carry it): refused in one line."""
    P_used = np.array([[1.03, 0.3, -0.01], [0.3, 0.0, 0.3], [-0.01, 0.3, 1.01]])  # what the firmware applied
    path, _ = _ardupilot_compass_capture(tmp_path, P_used)
    res, db = _saved(capsys, tmp_path, path, "--override", "test")
    cid = res["calibration_id"]
    code, text, err = run(capsys, "export", cid, "--format", "ardupilot", "--db", db)
    assert code == 2 and text == "" and err.count("\n") == 1, (code, text, err)
    assert "COMPASS_DIA_Y = 0 in use" in err and "only when all three are 0" in err and "broken calibration" in err


def test_an_all_zero_compass_diagonal_in_use_is_the_identity_with_the_off_diagonal_kept(capsys, tmp_path):
    """All three DIA zero (never set): correct_field uses 1, 1, 1 and still applies ODI."""
    P_used = np.array([[1.0, 0.02, -0.01], [0.02, 1.0, 0.015], [-0.01, 0.015, 1.0]])
    path, sim = _ardupilot_compass_capture(tmp_path, P_used, dia_in_use=np.zeros(3))
    res, db = _saved(capsys, tmp_path, path)
    code, text, err = run(capsys, "export", res["calibration_id"], "--format", "ardupilot", "--db", db)
    assert code == 0, err
    p = names_in(text, "ardupilot")
    h_true_mG = np.asarray(sim.truth["hard_iron"]) * 10.0
    # offsets within 1 mGauss of the truth (the fit's sigma is ~0.1 mGauss here)
    np.testing.assert_allclose([p[f"COMPASS_OFS_{a}"] for a in XYZ], -h_true_mG, atol=1.0)


def test_a_partly_zero_accelerometer_scale_in_use_is_refused_not_read_as_one(capsys, tmp_path):
    """AP_InertialSensor::init sets INS_ACCSCAL to (1,1,1) only when all three are zero
    (`_accel_scale[i].get().is_zero()`); _rotate_and_correct_accel multiplies by each as it is.
    INS_ACCSCAL_Z = 0 beside 1.012, 0.985 was read as 1 and composed on."""
    path, *_ = _board_corrected_capture(tmp_path, "ardupilot", 3)
    from station.capture import read_capture

    cap = read_capture(path)
    p = tmp_path / "z.csv"
    write_capture(p, Capture(meta=dict(cap.meta, **{"param.INS_ACCSCAL_Z": "0"}), columns=cap.columns, path=p))
    res, db = _saved(capsys, tmp_path, p)
    code, text, err = run(capsys, "export", res["calibration_id"], "--format", "ardupilot", "--db", db)
    assert code == 2 and text == "" and err.count("\n") == 1, (code, text, err)
    assert "INS_ACCSCAL_Z = 0 in use" in err and "AP_InertialSensor::init" in err


def test_px4_with_two_sensors_in_use_and_none_named_is_refused_not_slot_0(capsys, tmp_path):
    """A corrected PX4 capture that names no sensor (sensor_combined of a log before
    sensor_selection) with CAL_ACC0_ID and CAL_ACC1_ID both in use: the export composed with
    slot 0's parameters and wrote slot 0 without a word. Refused in one line; --instance picks."""
    path, *_ = _board_corrected_capture(tmp_path, "px4", 4)
    from station.capture import read_capture

    cap = read_capture(path)
    meta = {k: v for k, v in cap.meta.items() if k != "sensor_device_id"}
    meta.update({"param.CAL_ACC1_ID": "1441792", **{f"param.CAL_ACC1_{a}OFF": "0" for a in XYZ}})
    meta.update({f"param.CAL_ACC1_{a}SCALE": "1" for a in XYZ})
    p = tmp_path / "two.csv"
    write_capture(p, Capture(meta=meta, columns=cap.columns, path=p))
    res, db = _saved(capsys, tmp_path, p)
    cid = res["calibration_id"]
    code, text, err = run(capsys, "export", cid, "--format", "px4", "--db", db)
    assert code == 2 and text == "" and err.count("\n") == 1, (code, text, err)
    assert "CAL_ACC0_ID = 1310988 and CAL_ACC1_ID = 1441792 in use" in err and "--instance N" in err
    code, text, err = run(capsys, "export", cid, "--format", "px4", "--db", db, "--instance", "0")
    assert code == 0, err
    assert names_in(text, "px4")["CAL_ACC0_ID"] == 1310988


@pytest.mark.parametrize(
    "changed,says",
    [
        ("COMPASS_OFS_X,COMPASS_OFS_Y,COMPASS_OFS_Z", "COMPASS_OFS_X, COMPASS_OFS_Y, COMPASS_OFS_Z changed"),
        ("COMPASS_DIA_Y", "COMPASS_DIA_Y changed"),
        ("COMPASS_SCALE", "COMPASS_SCALE changed"),
    ],
)
def test_parameters_changed_during_the_log_are_not_composed_with(capsys, tmp_path, changed, says):
    """A log whose COMPASS_OFS changed mid-flight (COMPASS_LEARN) carries params_changed; the export
    composed the new parameters with the values at the start as if they had corrected every sample.
    Refused in one line naming the parameters."""
    P_used = np.array([[1.03, 0.02, -0.01], [0.02, 0.97, 0.015], [-0.01, 0.015, 1.01]])
    path, _ = _ardupilot_compass_capture(tmp_path, P_used)
    from station.capture import read_capture

    cap = read_capture(path)
    p = tmp_path / "changed.csv"
    write_capture(p, Capture(meta=dict(cap.meta, params_changed=changed), columns=cap.columns, path=p))
    res, db = _saved(capsys, tmp_path, p)
    code, text, err = run(capsys, "export", res["calibration_id"], "--format", "ardupilot", "--db", db)
    assert code == 2 and text == "" and err.count("\n") == 1, (code, text, err)
    assert says in err and "while the capture's data were logged" in err


@pytest.mark.parametrize("fmt", ["px4", "qgc"])
def test_px4_device_id_in_hex_as_px4_prints_it(capsys, db, fmt):
    """`--device-id 0x25000A` was refused by argparse ('invalid int value'), though PX4's
    `listener sensor_accel` and its drivers print a device id in hex (QA s26). Decimal and
    0x-hex name the same id; anything else is one line, exit 2, nothing written."""
    cid = _save(db, gyro_result(device="G"), gyro_unit="rad/s")
    decimal = run(capsys, "export", cid, "--format", fmt, "--device-id", "2424842", "--db", db)
    for spelling in ("0x25000A", "0x25000a", "0X25000A"):
        code, out, err = run(capsys, "export", cid, "--format", fmt, "--device-id", spelling, "--db", db)
        assert (code, err) == (0, ""), err
        assert "2424842" in out and out == decimal[1]
    for bad in ("25000A", "0x", "1.5", "0x25000G", "id7"):
        with pytest.raises(SystemExit) as exc:
            run(capsys, "export", cid, "--format", fmt, "--device-id", bad, "--db", db)
        out, err = capsys.readouterr()
        assert exc.value.code == 2 and out == "" and err.count("\n") == 1, err
        assert f"'{bad}' is no device id" in err and "0x" in err
