"""`station export` (known answers by applying each firmware's own correction) and `station recompute`."""

from __future__ import annotations

import json
import shutil
import subprocess

import numpy as np
import pytest
from db_testdata import accel_result, compass_result, gyro_result, ldv_result, small_capture

from db import Store
from tests.station_run import run_main as run
from tests.test_firmware_export import names_in

G0 = 9.80665  # the firmwares' standard gravity (GRAVITY_MSS, CONSTANTS_ONE_G)


def _save(db, result, **meta):
    m, cols = small_capture(device=result["device"], procedure=result["procedure"])
    m.pop("accel_unit")
    m["sensor_device_id"] = "1310988"  # PX4 applies a CAL_*n slot only to the sensor with this id
    m.update(meta)
    with Store(db) as s:
        return s.save_calibration(result, meta=m, columns=cols, allow_duplicate=True)


M_TRUE = [[1.02, 0.003, -0.002], [0.0, 0.985, 0.004], [0.0, 0.0, 1.01]]
B_TRUE = [0.12, -0.34, 0.56]


@pytest.mark.parametrize("unit,k", [("m/s^2", 1.0), ("g", G0)])
@pytest.mark.parametrize("fmt", ["ardupilot", "px4"])
def test_accel_tabletop_offsets_and_scales_reproduce_the_diagonal_model(capsys, db, unit, k, fmt):
    M = [[m * k for m in row] for row in M_TRUE]  # A [m/s^2] = B + M V: M in m/s^2 per capture unit
    cid = _save(db, accel_result(device="A", B=B_TRUE, M=M), accel_unit=unit)
    code, out, _ = run(capsys, "export", str(cid), "--format", fmt, "--db", db)
    assert code == 0
    p = names_in(out, fmt)
    names = ["INS_ACCOFFS_", "INS_ACCSCAL_"] if fmt == "ardupilot" else ["CAL_ACC0_{}OFF", "CAL_ACC0_{}SCALE"]
    rng = np.random.default_rng(1)
    for _ in range(5):
        v_raw = rng.normal(0, 1.0, 3)  # in the capture's unit
        a_fw = v_raw * k  # what the firmware's driver hands over, m/s^2
        for i, ax in enumerate("XYZ"):
            off = p[names[0] + ax] if fmt == "ardupilot" else p[names[0].format(ax)]
            scale = p[names[1] + ax] if fmt == "ardupilot" else p[names[1].format(ax)]
            firmware = (a_fw[i] - off) * scale  # both: subtract the offset, then scale
            station = B_TRUE[i] + M[i][i] * v_raw[i]  # A = B + M V without the cross terms
            assert firmware == pytest.approx(station, abs=1e-7)
    assert "# converted:" in out and "dropped: off-diagonal" in out and "0.004" in out
    if fmt == "px4":  # PX4 applies slot 0 only to the sensor whose id is CAL_ACC0_ID
        assert "param set CAL_ACC0_ID 1310988" in out and "param set CAL_ACC0_PRIO 50" in out


def test_accel_centrifuge_px4(capsys, db):
    r = {
        "procedure": "accel-centrifuge",
        "device": "C",
        "model": "N = S Phi [f + D f^2] + b",
        "params": {"S": [1.01, 0.99, 1.02], "b": [0.02, -0.01, 0.03], "D": [1e-4, 0, 0]},
        "uncertainty": {"S": [1e-4] * 3, "b": [1e-4] * 3, "D": [1e-5] * 3},
        "residual_rms": 0.001,
        "n_positions": 20,
        "warnings": [],
    }
    cid = _save(db, r, accel_unit="g")
    code, out, _ = run(capsys, "export", str(cid), "--format", "px4", "--db", db)
    p = names_in(out, "px4")
    f_g = np.array([0.3, -0.7, 1.1])
    N = np.array(r["params"]["S"]) * f_g + np.array(r["params"]["b"])  # in g, as the sensor reports
    for i, ax in enumerate("XYZ"):
        a = (N[i] * G0 - p[f"CAL_ACC0_{ax}OFF"]) * p[f"CAL_ACC0_{ax}SCALE"]
        assert a == pytest.approx(f_g[i] * G0, abs=1e-6)
    assert "dropped: D" in out


def _field(W, h, raw):
    return np.asarray(W) @ (raw - np.asarray(h))


@pytest.mark.parametrize("unit,nT", [("uT", 1e3), ("gauss", 1e5), ("nT", 1.0)])
def test_compass_ardupilot_and_px4_reproduce_the_field_norm(capsys, db, unit, nT):
    W = [[1.05, 0.02, -0.01], [0.0, 0.97, 0.03], [0.0, 0.0, 1.02]]
    W = [[w * 1.0 for w in row] for row in W]  # maps the capture unit to nT: scale by nT per unit
    W = [[w * nT / nT for w in row] for row in W]
    h = [12e3 / nT, -7e3 / nT, 3e3 / nT]  # 12, -7, 3 uT in the capture's unit (within COMPASS_OFFS_MAX)
    Wn = [[w * nT for w in row] for row in W]  # unit -> nT
    cid = _save(db, compass_result(device="M", hard_iron=h, soft_iron=Wn), mag_unit=unit)
    rng = np.random.default_rng(3)
    code, ap, _ = run(capsys, "export", str(cid), "--format", "ardupilot", "--db", db)
    code2, px, _ = run(capsys, "export", str(cid), "--format", "px4", "--db", db)
    assert code == code2 == 0
    a, p = names_in(ap, "ardupilot"), names_in(px, "px4")
    mat_ap = np.array(
        [
            [a["COMPASS_DIA_X"], a["COMPASS_ODI_X"], a["COMPASS_ODI_Y"]],
            [a["COMPASS_ODI_X"], a["COMPASS_DIA_Y"], a["COMPASS_ODI_Z"]],
            [a["COMPASS_ODI_Y"], a["COMPASS_ODI_Z"], a["COMPASS_DIA_Z"]],
        ]
    )
    ofs_ap = np.array([a[f"COMPASS_OFS_{x}"] for x in "XYZ"])
    mat_px = np.array(
        [
            [p["CAL_MAG0_XSCALE"], p["CAL_MAG0_XODIAG"], p["CAL_MAG0_YODIAG"]],
            [p["CAL_MAG0_XODIAG"], p["CAL_MAG0_YSCALE"], p["CAL_MAG0_ZODIAG"]],
            [p["CAL_MAG0_YODIAG"], p["CAL_MAG0_ZODIAG"], p["CAL_MAG0_ZSCALE"]],
        ]
    )
    off_px = np.array([p[f"CAL_MAG0_{x}OFF"] for x in "XYZ"])
    for _ in range(5):
        raw = rng.normal(0, 50.0, 3)  # capture units
        want_nT = np.linalg.norm(_field(Wn, h, raw))
        raw_mG, raw_G = raw * nT / 100.0, raw * nT / 1e5
        ap_mG = mat_ap @ (raw_mG + ofs_ap)  # AP_Compass_Backend::correct_field: add offsets, then matrix
        px_G = mat_px @ (raw_G - off_px)  # PX4 Magnetometer::Correct: subtract offset, then matrix
        assert np.linalg.norm(ap_mG) * 100.0 == pytest.approx(want_nT, rel=1e-6)
        assert np.linalg.norm(px_G) * 1e5 == pytest.approx(want_nT, rel=1e-6)
    assert "ArduPilot ADDS offsets" in ap and "PX4 subtracts it" in px


def test_gyro_offsets_and_instances(capsys, db):
    cid = _save(db, gyro_result(device="G", drift=(1e-4, -2e-4, 5e-5)), gyro_unit="deg/s")
    _, out, _ = run(capsys, "export", str(cid), "--format", "px4", "--instance", "1", "--db", db)
    assert names_in(out, "px4") == pytest.approx(
        {
            "CAL_GYRO1_XOFF": 1e-4,
            "CAL_GYRO1_YOFF": -2e-4,
            "CAL_GYRO1_ZOFF": 5e-5,
            "CAL_GYRO1_ID": 1310988,
            "CAL_GYRO1_PRIO": 50,
        }
    )
    _, out, _ = run(capsys, "export", str(cid), "--format", "ardupilot", "--instance", "2", "--db", db)
    assert set(names_in(out, "ardupilot")) == {"INS_GYR2OFFS_X", "INS_GYR2OFFS_Y", "INS_GYR2OFFS_Z"}
    assert "# calibration warning: no temperature column" in out
    code, _, err = run(capsys, "export", str(cid), "--format", "ardupilot", "--instance", "7", "--db", db)
    assert code == 2 and "--instance is 1 to 5 (IMUs; compasses 1 to 3)" in err  # s28: INS4_/INS5_


@pytest.mark.parametrize(
    "fmt, option, value",
    [
        ("ardupilot", "--device-id", "2424842"),
        ("json", "--device-id", "2424842"),
        ("c-header", "--instance", "1"),
        ("json", "--instance", "2"),
        ("px4", "--vehicle", "2,1"),
        ("ardupilot", "--vehicle", "1,1"),
    ],
)
def test_an_option_the_format_has_no_use_for_is_refused(capsys, db, fmt, option, value):
    """`--device-id` with `--format ardupilot` (ArduPilot has no such parameter: its slot is its
    instance), `--instance` with json or a C header, `--vehicle` with anything but a QGroundControl
    file were ignored without a word, exit 0: the file said nothing of what was asked. Refused in
    one line naming the formats that take it, as `import` refuses its options for other formats."""
    cid = _save(db, gyro_result(device="G"), gyro_unit="rad/s")
    code, out, err = run(capsys, "export", str(cid), "--format", fmt, option, value, "--db", db)
    assert code == 2 and out == "" and err.count("\n") == 1 and option in err and "applies to" in err, err
    code, out, err = run(capsys, "export", str(cid), "--format", fmt, "--db", db)
    assert code == 0 and out, err


@pytest.mark.parametrize("fmt", ["ardupilot", "px4"])
def test_refusals_are_one_line_exit_2(capsys, db, fmt):
    ldv = _save(db, ldv_result())
    volts = _save(db, accel_result(device="V"), accel_unit="V")
    code, out, err = run(capsys, "export", str(ldv), "--format", fmt, "--db", db)
    assert code == 2 and out == "" and err.count("\n") == 1 and "ldv" in err and "no parameters" in err
    code, out, err = run(capsys, "export", str(volts), "--format", fmt, "--db", db)
    assert code == 2 and out == "" and err.count("\n") == 1 and "raw 'V'" in err
    code, _, err = run(capsys, "export", "999", "--format", fmt, "--db", db)
    assert code == 2 and "no calibration 999" in err


def test_json_export_is_the_stored_result(capsys, db, tmp_path):
    r = accel_result(device="J")
    cid = _save(db, r)
    code, out, _ = run(capsys, "export", str(cid), "--format", "json", "--db", db)
    doc = json.loads(out)
    assert code == 0 and doc["result"] == r and doc["calibration_id"] == cid and len(doc["hash"]) == 64
    target = tmp_path / "out.json"
    assert run(capsys, "export", str(cid), "--format", "json", "-o", str(target), "--db", db)[1] == ""
    assert json.loads(target.read_text()) == doc


@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler on this machine")
def test_c_header_compiles_and_holds_the_values(capsys, db, tmp_path):
    device = 'IMU "q"\n*/ Ω'
    cid = _save(db, ldv_result(device=device))
    code, out, _ = run(capsys, "export", str(cid), "--format", "c-header", "--db", db)
    assert code == 0
    assert "static const float imu__q_ldv_beam2_alpha_deg = " in out  # names prefixed by the device
    assert "/* model: " in out and "/* units: velocities in m/s, angles in degrees */" in out
    (tmp_path / "cal.h").write_text(out)
    (tmp_path / "main.c").write_text(
        '#include <stdio.h>\n#include "cal.h"\nint main(void){\n'
        '  printf("%s|%.9g|%.9g|%.9g|%ld\\n", imu__q_ldv_device, imu__q_ldv_beam2_alpha_deg,\n'
        "         imu__q_ldv_sigma_beam3_dK, imu__q_ldv_condition_number, imu__q_ldv_calibration_id);\n"
        "  return 0;}\n"
    )
    exe = tmp_path / "main"
    subprocess.run(
        ["cc", "-Wall", "-Werror", "-Wno-unused-const-variable", "-o", str(exe), str(tmp_path / "main.c")],
        check=True,
        capture_output=True,
    )
    got = subprocess.run([str(exe)], check=True, capture_output=True).stdout.decode("utf-8").rstrip("\n")
    f32 = [f"{float(np.float32(x)):.9g}" for x in (60.1, 0.001, 3.2)]  # the values as float, printed back
    assert got == f"{device}|{'|'.join(f32)}|{cid}"


# --- recompute -------------------------------------------------------------------------


def test_recompute_without_a_capture_or_calibration_is_one_line(capsys, db):
    code, _, err = run(capsys, "recompute", "5", "--db", db)
    assert code == 2 and err.count("\n") == 1


def _calibrated_shared_capture(shared_data):
    """The first shared capture today's calibrators can do (skip only if none can)."""
    calibrate = pytest.importorskip("station.calibrate")
    if not hasattr(calibrate, "calibrate_capture"):
        pytest.skip("station.calibrate.calibrate_capture does not exist yet")
    from station.capture import read_capture
    from station.errors import UnsupportedError

    reasons = []
    for rel in [
        "wang2021_centrifuge/table1.capture.csv",
        "mpu6050_unc/mpu6050_unc_static_test.capture.csv",
        "imucal_ferraris/imucal_ferraris_labelled.capture.csv",
        "sunsided_marg/sunsided_full_sphere.capture.csv",
    ]:
        capture = read_capture(shared_data / rel)
        try:
            return capture, calibrate.calibrate_capture(capture)
        except UnsupportedError as exc:
            reasons.append(str(exc))
    pytest.skip("no procedure can calibrate yet: " + "; ".join(reasons))


def test_recompute_reports_differences_in_sigma(capsys, db, shared_data):
    capture, result = _calibrated_shared_capture(shared_data)
    from db.params import clean_json, flatten

    result = clean_json(result)
    values, sigmas = flatten(result["params"]), flatten(result["uncertainty"])
    name = next(n for n, s in sigmas.items() if s and values.get(n) is not None)
    with Store(db) as s:
        same = s.save_calibration(
            result, meta=capture.meta, columns=capture.columns, allow_duplicate=True, device_id="R"
        )
        older = json.loads(json.dumps(result))  # as if an older version had found +2 sigma on one parameter
        _shift(older["params"], name, 2.0 * sigmas[name])
        moved = s.save_calibration(
            older, meta=capture.meta, columns=capture.columns, allow_duplicate=True, device_id="R"
        )
    code, out, _ = run(capsys, "recompute", str(same), "--json", "--db", db)
    assert code == 0
    diffs = {d["param"]: d for d in json.loads(out)["differences"]}
    assert all(d["delta"] == 0 for d in diffs.values() if d["delta"] is not None)  # same code, same data
    if capture.header_line == len(capture.meta) + 1:  # file laid out as write_capture does: same line numbers
        assert json.loads(out)["recomputed"]["warnings"] == result["warnings"]
    code, out, _ = run(capsys, "recompute", str(moved), "--json", "--db", db)
    diffs = {d["param"]: d for d in json.loads(out)["differences"]}
    assert diffs[name]["delta_in_sigma"] == pytest.approx(-2.0, rel=1e-6)  # float rounding of value + 2 sigma
    code, out, _ = run(capsys, "recompute", str(moved), "--db", db)
    assert code == 0 and "largest change: 2.00 sigma" in out


def _shift(params, name, amount):
    """Add `amount` to the scalar at path `name` (B[0], beam1.dK) inside params."""
    import re

    tokens = re.findall(r"[^.\[\]]+|\[\d+\]", name)
    obj = params
    for tok in tokens[:-1]:
        obj = obj[int(tok[1:-1])] if tok.startswith("[") else obj[tok]
    last = tokens[-1]
    key = int(last[1:-1]) if last.startswith("[") else last
    obj[key] = obj[key] + amount


@pytest.mark.parametrize(
    ("argv", "option"),
    [
        (["export", "{cid}", "--format", "json", "-o", "{db}"], "-o"),
        (["export", "{cid}", "--format", "px4", "-o", "{link}"], "-o"),
        (["export-capture", "--calibration", "{cid}", "-o", "{db}"], "-o"),
        (["report", "{cid}", "--out", "{db}"], "--out"),
    ],
)
def test_an_output_that_is_the_database_is_refused_and_the_database_kept(tmp_path, capsys, db, argv, option):
    """`station export ID -o station.db --db station.db` replaced the whole database with the
    export (an atomic rename over it): every device and calibration gone. Refused, the
    database unchanged and still readable; also through a link to it."""
    cid = _save(db, gyro_result(device="G"))
    link = tmp_path / "link.db"
    link.symlink_to(db)
    before = open(db, "rb").read()
    args = [a.format(cid=cid, db=db, link=link) for a in argv]
    code, out, err = run(capsys, *args, "--db", db)
    assert code == 2 and out == "" and err.count("\n") == 1, err
    assert f"{option} is the station database: choose another name" in err
    assert open(db, "rb").read() == before
    with Store(db) as s:
        assert s.calibration(cid)["device_id"] == "G"


@pytest.mark.parametrize(
    "argv",
    [["export", "{cid}", "--format", "json"], ["export", "{cid}", "--format", "px4"], ["export-capture", "{cap}"]],
    ids=["export-json", "export-px4", "export-capture"],
)
def test_dash_as_output_is_standard_output_as_for_report(tmp_path, capsys, db, monkeypatch, argv):
    """`-o -` wrote a file named '-' in the current folder (report takes '-' as stdout, as its
    help says): the same export on stdout, no file made."""
    cid = _save(db, accel_result(device="A", B=B_TRUE, M=M_TRUE), accel_unit="m/s^2")
    with Store(db) as s:
        cap = s.calibration(cid)["capture_id"]
    monkeypatch.chdir(tmp_path)
    args = [a.format(cid=cid, cap=cap) for a in argv]
    code, plain, err = run(capsys, *args, "--db", db)
    assert code == 0 and plain, err
    code, dashed, err = run(capsys, *args, "-o", "-", "--db", db)
    assert code == 0 and err == ""
    assert dashed == plain
    assert not (tmp_path / "-").exists()
