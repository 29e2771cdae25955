"""Firmware exports read back by the world's own readers, and checked against real boards.

- PX4's own parameter lists, types and calibration values as PX4 stored them in the real logs
  of ../shared/data/px4_ulog/original (read by pyulog, PX4's own ULog library; SOURCE.md there:
  PX4/pyulog commit 3cf17793f14709713ab297d3743314c658874068, test/): a CubeOrange on
  v1.11.2 (CAL_*n_EN, no _PRIO, no CAL_MAGn_*ODIAG, an external compass in slot 1), an
  AUAV-X21 on an older PX4 (CAL_*_PRIME, CAL_GYROn_*SCALE), and two SITL builds (_PRIO, _ROT,
  ODIAG; one with CAL_GYROn_PRIO = -1).
- QGroundControl's reader of a .params file: mavlink/qgroundcontrol,
  src/FactSystem/ParameterManager.cc, ParameterManager::readParametersFromStream (commit
  e7680e08cb5469f5cd830623114d71770b540381): a line starting with '#' is skipped; any other is
  split on TAB and used only when it has exactly 5 fields (others are dropped without a word);
  field 1 must equal the vehicle's system id or the whole load is refused; a name the vehicle
  lacks is a "not currently on the vehicle" error and a type (MAV_PARAM_TYPE, field 5) other
  than the vehicle's own parameter type a "type mismatch" error; the value string is handed
  to the parameter as it is (an INT32 from an integer literal). `qgc_load` below follows it.
- PX4's shell: src/systemcmds/param/param.cpp `do_set` parses an INT32 value with strtol
  (base 10) and a FLOAT with strtod, so integer parameters are written as integer literals.
- MAVProxy's / pymavlink's reader of a .param file: pymavlink/mavparm.py MAVParmDict.load
  (pymavlink 2.4.50, the installed package): text after '#' dropped, ',' taken as a blank,
  a line of other than 2 fields reported "Invalid line" and skipped.
- MAVLink PARAM_SET/PARAM_VALUE: param_id is char[16] (mavlink common.xml), so no name over 16.
- PX4's rules for the priority and rotation of a calibration slot:
  src/lib/sensor_calibration/Magnetometer.cpp (commit 033e9cee3625392e07633088a3ebeb245a9f1dd4)
  and Accelerometer.cpp (commit 9abd968ef4edea9a2c187b0567c801dd8a03c84f), ParametersUpdate:
  a PRIO outside 0..100 is replaced by DEFAULT_EXTERNAL_PRIORITY (75) for an external sensor,
  DEFAULT_PRIORITY (50) for an internal one, silently for -1 ("the uninitialized parameter
  value"); an internal sensor's ROT is forced to -1, an external one's outside 0..ROTATION_MAX
  to 0; ParametersSave writes the priority it loaded (0 = disabled stays 0).
  Magnetometer.hpp (commit 021ee44aee5357b60f166f8e3cc1ed1c3f0b223f): DEFAULT_PRIORITY = 50,
  DEFAULT_EXTERNAL_PRIORITY = 75. module.yaml (src/modules/sensors): CAL_*n_PRIO values -1
  Uninitialized, 0 Disabled, 1..100. Utilities.cpp (commit
  3f5273e2360b61a81aea756f8373c5ac46443170) DeviceExternal: bus type UAVCAN, SERIAL, MAVLINK
  external, SIMULATION internal, I2C/SPI by the board's bus table; the bus type is the low 3
  bits of the device id (src/lib/drivers/device/Device.hpp, DeviceStructure, commit
  01462ce627b16b9d076e1f5c3560671caf128d4f: UNKNOWN 0, I2C 1, SPI 2, UAVCAN 3, SIMULATION 4,
  SERIAL 5).
- ArduPilot's own parameter list in a real DataFlash log (PARM records, read by pymavlink's
  DFReader): `ardupilot_round_trip` runs on pymavlink's tests/test.BIN (kept in tests/data/
  ardupilot_pymavlink, blob a39b77e3b75adc7dac38f052011f2039115de248: ArduPlane V3.8.2 on a
  Pixhawk, AHRS_ORIENTATION 8, two IMUs, three compasses) and on every .bin under
  ../shared/data/*/original: it reproduces INS_ACC{,2}OFFS/SCAL, INS_GYR{,2}OFFS and
  COMPASS_OFS/DIA/ODI{,2,3} exactly.
- ArduPilot's compass calibrator: libraries/AP_Compass/CompassCalibrator.cpp fit_acceptable:
  |offset| < _offset_max (COMPASS_OFFS_MAX), 0.2 < diag < 5.0, |offdiag| < 1.0, all strict.
"""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

import numpy as np
import pytest
from db_testdata import accel_result, compass_result, gyro_result, small_capture

from db import Store
from station.capture import read_capture
from tests.station_run import run_main as run

XYZ = "XYZ"
S = {"accel": "ACC", "gyro": "GYRO", "mag": "MAG"}
PROCEDURE = {"accel": "accel-tabletop", "gyro": "gyro-drift", "mag": "compass"}
TOPIC = {"accel": "sensor_accel", "gyro": "sensor_gyro", "mag": "sensor_mag"}
LOGS = (
    "sample.ulg",
    "sample_log_small.ulg",
    "sample_logging_tagged_and_default_params.ulg",
    "sample_px4_events.ulg",
)


def ulog(path, topics=()):
    pyulog = pytest.importorskip("pyulog")
    with contextlib.redirect_stdout(io.StringIO()):  # pyulog reports oddities on stdout
        return pyulog.ULog(str(path), list(topics))


def qgc_load(text: str, vehicle: dict, sysid: int = 1) -> dict:
    """What QGroundControl's readParametersFromStream sets on a vehicle whose parameters (name ->
    value, int for INT32, float for REAL32) are ``vehicle``; AssertionError for what it refuses
    or reports, and for a line it would drop without a word."""
    loaded = {}
    for line in text.split("\n"):
        if line.startswith("#") or line == "":
            continue
        fields = line.split("\t")
        assert len(fields) == 5, f"QGroundControl drops this line without a word: {line!r}"
        assert int(fields[0]) == sysid, f"saved from System Id {fields[0]}: the whole file is refused"
        comp, name, value, mav_type = int(fields[1]), fields[2], fields[3], int(fields[4])
        assert comp == 1, line  # MAV_COMP_ID_AUTOPILOT1: PX4's parameters
        assert name in vehicle, f"not currently on the vehicle: {comp}:{name}"
        want = 6 if isinstance(vehicle[name], int) else 9  # MAV_PARAM_TYPE_INT32 / REAL32
        assert mav_type == want, f"type mismatch: {comp}:{name} written as {mav_type}, the vehicle's is {want}"
        if mav_type == 6:
            assert re.fullmatch(r"-?\d+", value), f"{name}: INT32 from {value!r}"
            loaded[name] = int(value)
        else:
            loaded[name] = float(value)
    return loaded


def px4_shell_load(text: str, vehicle: dict) -> dict:
    """`param set NAME VALUE` lines as PX4's param command takes them (strtol for INT32)."""
    loaded = {}
    for line in text.splitlines():
        if line.startswith("#") or not line.strip():
            continue
        cmd, verb, name, value = line.split(" ")
        assert (cmd, verb) == ("param", "set") and name in vehicle, line
        if isinstance(vehicle[name], int):
            assert re.fullmatch(r"-?\d+", value), line
            loaded[name] = int(value)
        else:
            loaded[name] = float(value)
    return loaded


def _same(written, logged) -> bool:
    if isinstance(logged, int):
        return written == logged
    return bool(np.isclose(written, logged, rtol=2e-7, atol=1e-9))  # float32 as the log stores it


def _result_from_log(kind: str, params: dict, n: int, corrected: bool) -> dict:
    """The calibration that changes nothing: for data the board corrected, the identity on top
    of the parameters in use; for raw sensor data, the log's own slot-n parameters in the
    station's models (accel a = B + M v: M = diag(SCALE), B = -OFF * SCALE; gyro drift = OFF;
    compass m = W (d - h): h = OFF gauss, W = 1e5 nT/gauss * [SCALE, ODIAG] symmetric)."""
    p = f"CAL_{S[kind]}{n}_"
    if kind == "accel":
        if corrected:
            return accel_result(B=(0.0, 0.0, 0.0), M=np.eye(3))
        o = np.array([params[f"{p}{a}OFF"] for a in XYZ])
        s = np.array([params[f"{p}{a}SCALE"] for a in XYZ])
        return accel_result(B=-o * s, M=np.diag(s))
    if kind == "gyro":
        return gyro_result(drift=(0.0, 0.0, 0.0) if corrected else tuple(params[f"{p}{a}OFF"] for a in XYZ))
    if corrected:
        return compass_result(hard_iron=(0.0, 0.0, 0.0), soft_iron=(1e5 * np.eye(3)).tolist())
    Sm = np.diag([params[f"{p}{a}SCALE"] for a in XYZ])
    for a, (i, j) in zip(XYZ, ((0, 1), (0, 2), (1, 2))):
        Sm[i, j] = Sm[j, i] = params.get(f"{p}{a}ODIAG", 0.0)
    return compass_result(hard_iron=tuple(params[f"{p}{a}OFF"] for a in XYZ), soft_iron=(1e5 * Sm).tolist())


@pytest.mark.parametrize("kind", ["accel", "gyro", "mag"])
@pytest.mark.parametrize("name", LOGS)
def test_a_calibration_that_changes_nothing_exports_the_logs_own_parameters(capsys, tmp_path, shared_data, name, kind):
    """Import a real PX4 log (every instance of the sensor, raw topics and sensor_combined),
    calibrate with the correction that changes nothing, export: every name written must be in
    the board's own parameter list with its own type, and every value the one the board
    stored. Read back as QGroundControl and PX4's shell read them."""
    _px4_round_trip(capsys, tmp_path, shared_data / "px4_ulog" / "original" / name, kind)


@pytest.mark.parametrize("kind", ["accel", "gyro", "mag"])
def test_the_same_on_a_pixhawk_5_log(capsys, tmp_path, kind):
    """The same on a newer board's real log (PX4_FMU_V5, tests/data/px4_fmu_v5_robologs: four
    CAL_ACC slots, _PRIO 50, two IMUs), where sensor_combined mixes two IMUs (its
    sensor_selection changes while the samples run: the import says so and names no slot, so that
    source is left out; the raw topics are each one sensor's)."""
    _px4_round_trip(capsys, tmp_path, Path(__file__).resolve().parent / "data" / "px4_fmu_v5_robologs" /
                    "test_sensors.ulg", kind)  # fmt: skip


def _px4_round_trip(capsys, tmp_path, log, kind):
    u = ulog(log, [TOPIC[kind]])
    params = dict(u.initial_parameters)
    instances = sorted({d.multi_id for d in u.data_list if d.name == TOPIC[kind]})
    db = str(tmp_path / "s.db")
    done = []
    for source, insts in (("raw", instances), ("combined", [0])):
        for inst in insts:
            out = tmp_path / f"{kind}-{source}-{inst}.csv"
            code, _, err = run(
                capsys, "import", log, "--procedure", PROCEDURE[kind], "--instance", inst, "--source", source,
                "--out", out,
            )  # fmt: skip
            if code != 0:
                assert code == 2 and err.count("\n") == 1, err  # no such topic in this log: refused in one line
                continue
            if "sensors while the samples run" in err:
                continue  # sensor_combined mixes two sensors: no slot to reproduce
            meta = read_capture(out).meta
            corrected = meta["corrected"] == "true"
            dev = meta.get(f"{kind}_device_id")
            slots = [n for n in range(4) if dev is not None and params.get(f"CAL_{S[kind]}{n}_ID") == int(dev)]
            if not corrected and not slots:
                continue  # a sensor the board has no calibration for: nothing to reproduce
            result = _result_from_log(kind, params, slots[0] if slots else 0, corrected)
            m, cols = small_capture(procedure=PROCEDURE[kind])
            with Store(db) as s:
                cid = s.save_calibration(dict(result, device=meta["device"]), meta=meta, columns=cols)
            written = {}
            for fmt in ("px4", "qgc"):
                code, text, err = run(capsys, "export", cid, "--format", fmt, "--db", db)
                assert code == 0, (source, inst, err)
                got = qgc_load(text, params) if fmt == "qgc" else px4_shell_load(text, params)
                assert "names of PX4 v1.12 and later" not in text  # the board's own list decided
                assert written in ({}, got), "px4 and qgc files differ"
                written = got
            n = slots[0] if slots else int(re.search(rf"CAL_{S[kind]}(\d)_ID", " ".join(written))[1])
            assert {f"CAL_{S[kind]}{n}_ID", *(f"CAL_{S[kind]}{n}_{a}OFF" for a in XYZ)} <= set(written), written
            changed = {k: (v, params[k]) for k, v in written.items() if not _same(v, params[k])}
            assert not changed, (source, inst, changed)
            done.append((source, inst))
    assert done  # every log holds this kind of sensor, calibrated


def test_an_external_compass_keeps_its_slot_rotation_and_the_firmware_it_runs(capsys, tmp_path, shared_data):
    """The CubeOrange log's external compass (sensor_mag[1].is_external = 1, CAL_MAG1_ROT = 0,
    PX4 v1.11: no CAL_MAG1_PRIO): its calibration goes to slot 1 with ROT 0 as the board had it,
    and no priority is written for a firmware that has none; the import says it is external."""
    log = shared_data / "px4_ulog" / "original" / "sample_log_small.ulg"
    params = ulog(log, ["sensor_mag"]).initial_parameters
    assert params["CAL_MAG1_ROT"] == 0 and "CAL_MAG1_PRIO" not in params  # the firmware as it is
    out = tmp_path / "mag1.csv"
    code, _, err = run(capsys, "import", log, "--procedure", "compass", "--instance", 1, "--out", out)
    assert code == 0, err
    meta = read_capture(out).meta
    assert meta["mag_external"] == "true" and meta["mag_device_id"] == "592905"
    m, cols = small_capture(procedure="compass")
    db = str(tmp_path / "s.db")
    with Store(db) as s:
        cid = s.save_calibration(compass_result(device=meta["device"], hard_iron=(0.03, 0.5, -0.4),
                                                soft_iron=(1e5 * np.eye(3)).tolist()), meta=meta, columns=cols)  # fmt: skip
    code, text, err = run(capsys, "export", cid, "--format", "qgc", "--db", db)
    assert code == 0, err
    got = qgc_load(text, params)
    assert got["CAL_MAG1_ID"] == 592905 and got["CAL_MAG1_ROT"] == 0 and "CAL_MAG1_PRIO" not in got
    assert got["CAL_MAG1_YOFF"] == pytest.approx(0.5)


def test_a_v1_11_combined_compass_is_the_selected_one_and_composes_in_its_own_slot(capsys, tmp_path, shared_data):
    """PX4 1.11's vehicle_magnetometer has no device_id: it carries the selected compass, which
    sensor_selection.mag_device_id names (592905 in the CubeOrange log, the external one,
    CAL_MAG1, ROT 0). The import read no id, and the export fell back to slot 0 (the internal
    compass, disabled) with the board rotation SENS_BOARD_ROT = 4 (yaw 180): a hard-iron fit on
    data the external compass measured went, with x and y flipped, to another sensor. Now the
    capture names the selected compass and the export composes PX4's own model in its slot:
    m = R S (raw - OFF), R = Dcm(SENS_BOARD_{X,Y,Z}_OFF) for an external compass with ROT 0,
    so a fitted h (corrected data, gauss) gives OFF = OFF_in_use + S^-1 R^T h."""
    log = shared_data / "px4_ulog" / "original" / "sample_log_small.ulg"
    u = ulog(log, ["sensor_selection"])
    params = u.initial_parameters
    selected = int(_topic_values(u, "sensor_selection", "mag_device_id"))
    assert selected == params["CAL_MAG1_ID"] == 592905 and params["CAL_MAG1_ROT"] == 0  # the log as it is
    out = tmp_path / "mag.csv"
    code, _, err = run(capsys, "import", log, "--procedure", "compass", "--source", "combined", "--out", out)
    assert code == 0, err
    meta = read_capture(out).meta
    assert meta["mag_device_id"] == str(selected) and meta["corrected"] == "true"
    h_G = np.array([0.03, 0.05, -0.04])
    m, cols = small_capture(procedure="compass")
    db = str(tmp_path / "s.db")
    with Store(db) as s:
        cid = s.save_calibration(compass_result(device=meta["device"], hard_iron=tuple(h_G),
                                                soft_iron=(1e5 * np.eye(3)).tolist()), meta=meta, columns=cols)  # fmt: skip
    code, text, err = run(capsys, "export", cid, "--format", "qgc", "--db", db)
    assert code == 0, err
    got = qgc_load(text, params)
    assert got["CAL_MAG1_ID"] == selected and not any(k.startswith("CAL_MAG0") for k in got), got
    x, y, z = (np.radians(params[f"SENS_BOARD_{a}_OFF"]) for a in XYZ)
    Rx = np.array([[1, 0, 0], [0, np.cos(x), -np.sin(x)], [0, np.sin(x), np.cos(x)]])
    Ry = np.array([[np.cos(y), 0, np.sin(y)], [0, 1, 0], [-np.sin(y), 0, np.cos(y)]])
    Rz = np.array([[np.cos(z), -np.sin(z), 0], [np.sin(z), np.cos(z), 0], [0, 0, 1]])
    R = Rz @ Ry @ Rx  # matrix::Dcm(Euler(roll, pitch, yaw)): 3-2-1
    S_old = np.diag([params[f"CAL_MAG1_{a}SCALE"] for a in XYZ])
    o_old = np.array([params[f"CAL_MAG1_{a}OFF"] for a in XYZ])
    want = o_old + np.linalg.solve(S_old, R.T @ h_G)
    assert np.allclose([got[f"CAL_MAG1_{a}OFF"] for a in XYZ], want, atol=2e-7), (got, want)


@pytest.mark.parametrize("fmt", ["px4", "qgc"])
def test_an_instance_that_is_another_sensors_slot_is_refused(capsys, tmp_path, shared_data, fmt):
    """The SITL log's selected accelerometer (1310988) is CAL_ACC0; `--instance 1` wrote
    CAL_ACC1_ID 1310988 over the slot of the sensor 1310996 (two slots then claim one sensor,
    the other is left uncalibrated), and composed the corrected data's fit with CAL_ACC1's
    offsets, another sensor's: XOFF 0.0097 - 0.1 instead of -0.039 - 0.1. Now refused in one
    line naming the slot the firmware applies; without --instance (or with 0) it is written."""
    log = shared_data / "px4_ulog" / "original" / "sample_px4_events.ulg"
    params = ulog(log, ["sensor_combined"]).initial_parameters
    assert params["CAL_ACC0_ID"] == 1310988 and params["CAL_ACC1_ID"] == 1310996  # the log as it is
    out = tmp_path / "acc.csv"
    code, _, err = run(capsys, "import", log, "--procedure", "accel-tabletop", "--source", "combined", "--out", out)
    assert code == 0, err
    meta = read_capture(out).meta
    assert meta["accel_device_id"] == "1310988" and meta["corrected"] == "true"
    m, cols = small_capture(procedure="accel-tabletop")
    db = str(tmp_path / "s.db")
    with Store(db) as s:
        cid = s.save_calibration(accel_result(device=meta["device"], B=(0.1, 0.0, 0.0), M=np.eye(3)), meta=meta,
                                 columns=cols)  # fmt: skip
    code, text, err = run(capsys, "export", cid, "--format", fmt, "--instance", "1", "--db", db)
    assert code == 2 and text == "" and err.count("\n") == 1, (text, err)
    assert "slot 0" in err and "CAL_ACC0_ID" in err, err
    for extra in ([], ["--instance", "0"]):
        code, text, err = run(capsys, "export", cid, "--format", fmt, *extra, "--db", db)
        assert code == 0, err
        got = qgc_load(text, params) if fmt == "qgc" else px4_shell_load(text, params)
        assert got["CAL_ACC0_ID"] == 1310988 and "CAL_ACC1_ID" not in got
        assert got["CAL_ACC0_XOFF"] == pytest.approx(params["CAL_ACC0_XOFF"] - 0.1, abs=1e-7)


def _topic_values(u, name, field):
    """The one value ``field`` of topic ``name`` holds over the log (asserted unique)."""
    values = {v for d in u.data_list if d.name == name for v in d.data[field].tolist()}
    assert len(values) == 1, values
    return values.pop()


def _px4_export(capsys, db, kind, device_id, **meta):
    result = {"accel": accel_result, "gyro": gyro_result, "mag": compass_result}[kind](device=f"{kind}{len(meta)}")
    m, cols = small_capture(procedure=PROCEDURE[kind], **{f"{kind}_unit": {"accel": "m/s^2", "gyro": "rad/s",
                                                                            "mag": "uT"}[kind]}, **meta)  # fmt: skip
    with Store(db) as s:
        cid = s.save_calibration(result, meta=m, columns=cols, allow_duplicate=True)
    code, text, err = run(capsys, "export", cid, "--format", "px4", "--device-id", device_id, "--db", db)
    assert code == 0, err
    lines = dict(line.split(" ")[2:] for line in text.splitlines() if line.startswith("param set"))
    return {k: int(v) for k, v in lines.items() if k.endswith(("_PRIO", "_ROT", "_ID"))}, text


def _devid(bus_type: int, bus: int = 1, address: int = 0x1E, devtype: int = 0x09) -> int:
    """A PX4 device id (Device.hpp DeviceStructure: bus_type:3, bus:5, address:8, devtype:8)."""
    return bus_type | bus << 3 | address << 8 | devtype << 16


@pytest.mark.parametrize(
    "kind,device_id,meta,prio,says",
    [
        # no parameters in use: PX4's own default for the sensor, from what the capture says of it
        ("mag", _devid(3), {}, 75, "default for an external sensor"),  # UAVCAN: external
        ("mag", _devid(5), {}, 75, "default for an external sensor"),  # SERIAL: external
        ("mag", 197388, {}, 50, "default for an internal sensor"),  # SITL's (SIMULATION) compass
        ("mag", 592905, {"mag_external": "true"}, 75, "external"),  # I2C, the log's is_external
        ("mag", 589858, {"mag_external": "false"}, 50, "internal"),  # SPI, the log's is_external
        (
            "mag",
            592905,
            {},
            -1,
            "replaces -1 (Uninitialized) with 75 for an external sensor, 50 for an internal",
        ),  # I2C, nothing says: PX4 picks on load
        ("accel", _devid(3), {}, 75, "external"),
        ("gyro", 1310988, {}, 50, "internal"),
        # in use: kept as PX4's own calibration keeps it, unless PX4 would reset it
        ("mag", 592905, {"firmware": "px4", "param.CAL_MAG0_ID": "592905", "param.CAL_MAG0_PRIO": "0"}, 0, "disabled"),
        ("gyro", 1310988, {"firmware": "px4", "param.CAL_GYRO0_PRIO": "-1"}, -1, None),  # sample_px4_events.ulg
        ("mag", 592905, {"firmware": "px4", "param.CAL_MAG0_PRIO": "100"}, 100, None),
        ("mag", 592905, {"firmware": "px4", "param.CAL_MAG0_PRIO": "150", "param.CAL_MAG0_ROT": "2"}, 75, "outside"),
    ],
)
def test_px4_priority_is_what_px4s_own_calibration_leaves(capsys, tmp_path, kind, device_id, meta, prio, says):
    p, text = _px4_export(capsys, str(tmp_path / "s.db"), kind, device_id, **meta)
    assert p[f"CAL_{S[kind]}0_PRIO"] == prio, text
    if says:
        assert says in text
    assert p[f"CAL_{S[kind]}0_ID"] == device_id
    # without the board's own list the firmware's version is unknown, and the file says for which it is
    assert "names of PX4 v1.12 and later" in text


def test_px4_rotation_is_the_one_in_use_or_none(capsys, tmp_path):
    """ROT is the mounting of an external sensor: the station cannot see it, so it writes the
    one in use and otherwise none, saying what to set (PX4 resets an external sensor's ROT that
    is not 0..40 to 0, an internal sensor's to -1, its default)."""
    db = str(tmp_path / "s.db")
    p, text = _px4_export(capsys, db, "mag", _devid(3))
    assert "CAL_MAG0_ROT" not in p and "mounting rotation" in text
    p, text = _px4_export(capsys, db, "mag", 592905, **{"param.CAL_MAG0_ROT": "6", "param.CAL_MAG0_ID": "592905"})
    assert p["CAL_MAG0_ROT"] == 6 and p["CAL_MAG0_PRIO"] == 75  # ROT >= 0 in use: PX4 treats it as external
    # the log's own is_external against the ROT in use: PX4 resets ROT as ParametersUpdate does
    p, text = _px4_export(capsys, db, "mag", 592905, mag_external="true", **{"param.CAL_MAG0_ROT": "-1"})
    assert p["CAL_MAG0_ROT"] == 0 and "resets it to for an external sensor" in text
    p, text = _px4_export(capsys, db, "mag", 589858, mag_external="false", **{"param.CAL_MAG0_ROT": "4"})
    assert p["CAL_MAG0_ROT"] == -1 and p["CAL_MAG0_PRIO"] == 50 and "for an internal sensor" in text


def test_ardupilot_param_file_reads_back_through_pymavlink(capsys, tmp_path):
    """Every ArduPilot export (each kind, instance 1..3) loaded by pymavlink's MAVParmDict.load,
    as MAVProxy's `param load` does: no invalid line, the same names and values, names of at
    most 16 characters (MAVLink param_id), even with a device name holding ',' and '#'."""
    mavparm = pytest.importorskip("pymavlink.mavparm")
    db = str(tmp_path / "s.db")
    cids = []
    for result, meta in (
        (accel_result(device="A,1 # x"), {"accel_unit": "m/s^2"}),
        (gyro_result(device="G,1"), {"gyro_unit": "rad/s"}),
        (compass_result(device="M#1"), {"mag_unit": "uT"}),
    ):
        m, cols = small_capture(procedure=result["procedure"], device=result["device"], **meta)
        with Store(db) as s:
            cids.append(s.save_calibration(result, meta=m, columns=cols))
    for cid in cids:
        for inst in (1, 2, 3):
            code, text, err = run(capsys, "export", cid, "--format", "ardupilot", "--instance", inst, "--db", db)
            assert code == 0, err
            path = tmp_path / f"{cid}-{inst}.param"
            path.write_text(text)
            ours = dict(line.split(",") for line in text.splitlines() if not line.startswith("#"))
            loaded = mavparm.MAVParmDict()
            said = io.StringIO()
            with contextlib.redirect_stdout(said):
                assert loaded.load(str(path))
            assert "Invalid line" not in said.getvalue(), said.getvalue()
            assert set(loaded) == set(ours) and all(len(n) <= 16 for n in loaded)
            assert all(loaded[n] == float(v) for n, v in ours.items())


def test_ardupilot_compass_bounds_are_strict_as_fit_acceptable(capsys, tmp_path):
    """fit_acceptable takes |offset| < COMPASS_OFFS_MAX, not <=: an offset of exactly
    COMPASS_OFFS_MAX is one the firmware's own calibration would reject."""
    db = str(tmp_path / "s.db")
    m, cols = small_capture(procedure="compass", mag_unit="uT", **{"param.COMPASS_OFFS_MAX": "1000"})
    with Store(db) as s:  # 100 uT = 1000 mGauss
        cid = s.save_calibration(
            compass_result(device="M", hard_iron=(100.0, 0.0, 0.0), soft_iron=(1e3 * np.eye(3)).tolist()),
            meta=m, columns=cols,
        )  # fmt: skip
    code, out, err = run(capsys, "export", cid, "--format", "ardupilot", "--db", db)
    assert code == 2 and out == "" and err.count("\n") == 1 and "COMPASS_OFS_X" in err and "COMPASS_OFFS_MAX" in err
    m["param.COMPASS_OFFS_MAX"] = "1001"
    with Store(db) as s:
        cid = s.save_calibration(
            compass_result(device="M2", hard_iron=(100.0, 0.0, 0.0), soft_iron=(1e3 * np.eye(3)).tolist()),
            meta=m, columns=cols,
        )  # fmt: skip
    code, out, err = run(capsys, "export", cid, "--format", "ardupilot", "--db", db)
    assert code == 0 and "COMPASS_OFS_X,-1000" in out, err


def ardupilot_round_trip(capsys, tmp_path, log) -> list:
    """Import each IMU and compass of an ArduPilot DataFlash log, calibrate with the correction
    that changes nothing (the data are the board's corrected ones), export: the .param file,
    read by pymavlink's MAVParmDict.load, must hold only names of the log's own PARM list (read
    by pymavlink's DFReader) with the values the board stored. Returns what was checked."""
    from pymavlink import DFReader, mavparm

    reader = DFReader.DFReader_binary(str(log), zero_time_base=True)
    params = {}
    while (m := reader.recv_match(type="PARM")) is not None:
        params.setdefault(m.Name, m.Value)  # the first value, as the import's param.* holds
    db = str(tmp_path / "ap.db")
    done = []
    for kind in ("accel", "gyro", "mag"):
        for inst in range(3):
            out = tmp_path / f"ap-{kind}-{inst}.csv"
            code, _, err = run(capsys, "import", log, "--procedure", PROCEDURE[kind], "--instance", inst, "--out", out)
            if code != 0:
                assert code == 2 and err.strip().count("\n") <= 1, err  # no such sensor: one line
                continue
            meta = read_capture(out).meta
            assert meta["corrected"] == "true" and meta["firmware"] == "ardupilot"
            result = _result_from_log(kind, params, 0, corrected=True)
            if kind == "mag":  # the identity in the capture's unit (mgauss, gauss, uT: nT per unit)
                from solvers.units import si_factor

                result = compass_result(hard_iron=(0.0, 0.0, 0.0), soft_iron=(si_factor("mag", meta["mag_unit"]) *
                                                                               np.eye(3)).tolist())  # fmt: skip
            m, cols = small_capture(procedure=PROCEDURE[kind])
            with Store(db) as s:
                cid = s.save_calibration(dict(result, device=f"{meta.get('device', 'ap')}-{kind}{inst}"), meta=meta,
                                         columns=cols)  # fmt: skip
            code, text, err = run(capsys, "export", cid, "--format", "ardupilot", "--db", db)
            assert code == 0, (kind, inst, err)
            path = tmp_path / f"ap-{kind}-{inst}.param"
            path.write_text(text)
            loaded = mavparm.MAVParmDict()
            said = io.StringIO()
            with contextlib.redirect_stdout(said):
                assert loaded.load(str(path))
            assert "Invalid line" not in said.getvalue(), said.getvalue()
            assert loaded and set(loaded) <= set(params), set(loaded) - set(params)
            changed = {k: (v, params[k]) for k, v in loaded.items() if not _same(v, params[k])}
            assert not changed, (kind, inst, changed)
            done.append((kind, inst, sorted(loaded)))
    return done


def test_a_calibration_that_changes_nothing_exports_an_ardupilot_logs_own_parameters(capsys, tmp_path, shared_data):
    """The same as for PX4 on every real ArduPilot DataFlash log: pymavlink's own test log
    (tests/data/ardupilot_pymavlink, SOURCE.md there) and any .bin under ../shared/data."""
    here = Path(__file__).resolve().parent / "data"
    logs = sorted(p for p in [*here.glob("*/*"), *shared_data.glob("*/original/*")] if p.suffix.lower() == ".bin")
    assert logs
    for log in logs:
        assert ardupilot_round_trip(capsys, tmp_path, log), log


def test_an_ardupilot_instance_that_is_another_imus_is_refused(capsys, tmp_path):
    """pymavlink's ArduPlane log: IMU[0] is INS_ACC_ID (1246730), IMU[1] INS_ACC2_ID. A fit on
    IMU[0]'s corrected data exported with `--instance 2` composed with INS_ACC2OFFS, the other
    IMU's offsets, and wrote them as that IMU's. Refused now; the sensor's own slot is written."""
    log = Path(__file__).resolve().parent / "data" / "ardupilot_pymavlink" / "test.BIN"
    out = tmp_path / "imu0.csv"
    code, _, err = run(capsys, "import", log, "--procedure", "accel-tabletop", "--instance", "0", "--out", out)
    assert code == 0, err
    meta = read_capture(out).meta
    assert meta["accel_device_id"] == meta["param.INS_ACC_ID"] != meta["param.INS_ACC2_ID"]
    m, cols = small_capture(procedure="accel-tabletop")
    db = str(tmp_path / "s.db")
    with Store(db) as s:
        cid = s.save_calibration(accel_result(device="AP", B=(0.1, 0.0, 0.0), M=np.eye(3)), meta=meta, columns=cols)
    code, text, err = run(capsys, "export", cid, "--format", "ardupilot", "--instance", "2", "--db", db)
    assert code == 2 and text == "" and err.count("\n") == 1 and "INS_ACC_ID" in err, (text, err)
    code, text, err = run(capsys, "export", cid, "--format", "ardupilot", "--instance", "1", "--db", db)
    assert code == 0 and "INS_ACCOFFS_X," in text and "INS_ACC2OFFS" not in text, err


def test_older_px4_gyro_scales_in_use_divide_the_composed_drift(capsys, tmp_path, shared_data):
    """Older PX4 has CAL_GYROn_{X,Y,Z}SCALE (sample.ulg's own list holds them) and its driver gave
    (w - OFF) * SCALE (src/lib/drivers/gyroscope/PX4Gyroscope.cpp, PX4Gyroscope::update of the
    v1.10 line: `((raw * scaling) - _calibration_offset).emult(_calibration_scale)`): a drift D
    seen in those data is D / SCALE in the driver's input, so OFF = OFF_in_use + D / SCALE.
    With scales 1.05, 0.95, 1.0 the composed offsets were OFF_in_use + D, off by 5 %."""
    in_log = ulog(shared_data / "px4_ulog" / "original" / "sample.ulg", ["sensor_combined"]).initial_parameters
    assert {"CAL_GYRO0_XSCALE", "CAL_GYRO0_XOFF"} <= set(in_log) and "CAL_GYRO0_PRIO" not in in_log
    o_old, s_old, D = np.array([0.01, -0.02, 0.005]), np.array([1.05, 0.95, 1.0]), np.array([0.021, -0.019, 0.003])
    meta = {"corrected": "true", "firmware": "px4", "gyro_device_id": "2162688", "param.CAL_GYRO0_ID": "2162688",
            "param.SENS_BOARD_ROT": "0"}  # fmt: skip
    meta.update({f"param.CAL_GYRO0_{a}OFF": repr(float(o_old[i])) for i, a in enumerate(XYZ)})
    meta.update({f"param.CAL_GYRO0_{a}SCALE": repr(float(s_old[i])) for i, a in enumerate(XYZ)})
    m, cols = small_capture(procedure="gyro-drift", gyro_unit="rad/s", **meta)
    db = str(tmp_path / "s.db")
    with Store(db) as s:
        cid = s.save_calibration(gyro_result(device="old-px4", drift=tuple(D)), meta=m, columns=cols)
    code, text, err = run(capsys, "export", cid, "--format", "qgc", "--db", db)
    assert code == 0, err
    got = qgc_load(text, in_log)
    assert np.allclose([got[f"CAL_GYRO0_{a}OFF"] for a in XYZ], o_old + D / s_old, rtol=1e-6, atol=1e-9)
    assert "CAL_GYRO0_PRIO" not in got and "drift / SCALE_in_use" in text


# --- every name, type, index range, unit and range against the firmwares' own definitions ---
# tests/data/firmware_params holds the calibration parameters extracted from the firmwares' own
# definitions (SOURCE.md there: PX4 src/modules/sensors/module.yaml at 5cda32d5; ArduPilot
# AP_InertialSensor.cpp var_info at 002f23e3 and AP_Compass.cpp var_info at 7e87c92e).
FW_PARAMS = Path(__file__).resolve().parent / "data" / "firmware_params"
# the upstream @Units / unit: spellings, as SI factors (m/s^2, rad/s, nT per unit)
UPSTREAM_UNIT = {"m/s^2": 1.0, "m/s/s": 1.0, "rad/s": 1.0, "gauss": 1e5, "mGauss": 1e2}


def _rows(name: str) -> list[list[str]]:
    lines = (FW_PARAMS / name).read_text(encoding="utf-8").splitlines()
    return [line.split("\t") for line in lines if line and not line.startswith("#")]


def px4_definitions() -> dict:
    """name -> (type, unit, min, max) for every instance module.yaml defines (${i} = 0..3)."""
    out = {}
    for name, typ, unit, lo, hi in _rows("px4_sensors_module_yaml.tsv"):
        for i in range(4):  # num_instances: 4, instance_start: 0
            out[name.replace("${i}", str(i))] = (
                typ,
                unit,
                None if lo == "-" else float(lo),
                None if hi == "-" else float(hi),
            )
    return out


def ardupilot_definitions() -> dict:
    """name -> (unit, min, max, readonly), a vector parameter as its _X, _Y, _Z."""
    out = {}
    for name, _index, vector, unit, lo, hi, ro in _rows("ardupilot_var_info.tsv"):
        spec = (unit, None if lo == "-" else float(lo), None if hi == "-" else float(hi), ro == "yes")
        for n in [f"{name}_{a}" for a in XYZ] if vector == "yes" else [name]:
            out[n] = spec
    return out


def _parse(text: str, fmt: str) -> dict:
    """name -> (value text, QGC type or None) of an exported file, as its reader splits it."""
    out = {}
    for line in text.splitlines():
        if not line.strip() or line.startswith("#"):
            continue
        if fmt == "ardupilot":
            name, value = line.split(",")
            out[name] = (value, None)
        elif fmt == "px4":
            _, _, name, value = line.split(" ")
            out[name] = (value, None)
        else:
            _, _, name, value, typ = line.split("\t")
            out[name] = (value, int(typ))
    return out


def _upstream_exports(capsys, db):
    """(kind, fmt, instance, text) for a modest calibration of each kind, every format and every
    instance the CLI takes, with the physical offsets each one holds (SI: m/s^2, rad/s, nT)."""
    hard_iron_uT = (10.0, -5.0, 2.0)
    cals = {
        "accel": (accel_result(device="A", B=(0.1, -0.2, 0.3), M=np.diag([1.01, 0.99, 1.0])), {"accel_unit": "m/s^2"}),
        "gyro": (gyro_result(device="G", drift=(0.01, -0.02, 0.03)), {"gyro_unit": "rad/s"}),
        "mag": (compass_result(device="M", hard_iron=hard_iron_uT, soft_iron=(1e3 * np.eye(3)).tolist()),
                {"mag_unit": "uT"}),
    }  # fmt: skip
    out = []
    for kind, (result, meta) in cals.items():
        m, cols = small_capture(procedure=result["procedure"], device=result["device"], sensor_device_id="1310988",
                                **meta)  # fmt: skip
        with Store(db) as s:
            cid = s.save_calibration(result, meta=m, columns=cols)
        for fmt, instances in (("ardupilot", (1, 2, 3)), ("px4", (0, 1, 2, 3)), ("qgc", (0, 1, 2, 3))):
            for inst in instances:
                code, text, err = run(capsys, "export", cid, "--format", fmt, "--instance", inst, "--db", db)
                assert code == 0, (kind, fmt, inst, err)
                out.append((kind, fmt, inst, text))
    return out


def test_every_exported_name_type_unit_and_range_is_the_firmwares_own(capsys, tmp_path):
    """Every parameter every export writes (accel, gyro, compass; .param, `param set`, QGC
    .params; every instance the CLI accepts) against the list extracted from the firmwares' own
    definitions (tests/data/firmware_params, SOURCE.md there):

    - PX4/PX4-Autopilot src/modules/sensors/module.yaml, commit
      5cda32d5565b9047eb792056cb8c2aaf6da5c2a3: CAL_{ACC,GYRO,MAG}${i}_* with num_instances 4
      (__max_num_sensor_instances, line 1) and instance_start 0; type int32/enum (QGC type 6) or
      float (9); unit (m/s^2, rad/s, gauss); min/max (SCALE 0.1..3.0, ROT -1..40, MAG ROT -1..100).
    - ArduPilot/ardupilot libraries/AP_InertialSensor/AP_InertialSensor.cpp, commit
      002f23e3d574306a293450bfbdfe5abb59ea2c96, AP_InertialSensor::var_info: GYROFFS (index 3),
      GYR2OFFS (7), GYR3OFFS (10), ACCSCAL (12, @Range 0.8 1.2), ACCOFFS (13, @Units m/s/s,
      @Range -3.5 3.5), ACC2SCAL/ACC2OFFS (14/15), ACC3SCAL/ACC3OFFS (16/17).
    - ArduPilot/ardupilot libraries/AP_Compass/AP_Compass.cpp, commit
      7e87c92e0c89f990666f6f8a452fbea70404b047, Compass::var_info: OFS (1, @Units mGauss,
      @Range -400 400), OFS2 (10), OFS3 (13), DEV_ID* (15-17, @ReadOnly), DIA/ODI (24/25),
      DIA2/ODI2 (26/27), DIA3/ODI3 (28/29), OFFS_MAX (31, @Range 500 3000), SCALE* (40-42).

    Each value must lie in the documented range, an ArduPilot @ReadOnly parameter must not be
    written, the QGC type must be the definition's, and an offset written in the definition's
    unit must be the calibration's physical offset."""
    px4, ap = px4_definitions(), ardupilot_definitions()
    for kind, fmt, inst, text in _upstream_exports(capsys, str(tmp_path / "s.db")):
        got = _parse(text, fmt)
        assert got, (kind, fmt, inst, text)
        for name, (value, qgc_type) in got.items():
            if fmt == "ardupilot":
                assert name in ap, f"{name}: not in ArduPilot's var_info"
                unit, lo, hi, readonly = ap[name]
                assert not readonly, f"{name} is @ReadOnly in ArduPilot"
            else:
                assert name in px4, f"{name}: not in PX4's module.yaml"
                typ, unit, lo, hi = px4[name]
                if qgc_type is not None:
                    assert qgc_type == (9 if typ == "float" else 6), (name, qgc_type, typ)
                if typ != "float":
                    assert re.fullmatch(r"-?\d+", value), (name, value)
            v = float(value)
            assert (lo is None or v >= lo) and (hi is None or v <= hi), f"{name} = {v} outside {lo}..{hi}"
        # the offsets in the definition's unit: accel B = -o*s (o m/s^2), gyro drift = o, mag h (uT)
        off = {
            "accel": [n for n in got if n.endswith(("XOFF", "YOFF", "ZOFF")) or "ACC" in n and "OFFS_" in n],
            "gyro": [n for n in got if n.endswith(("XOFF", "YOFF", "ZOFF")) or "GYR" in n and "OFFS_" in n],
            "mag": [n for n in got if n.endswith(("XOFF", "YOFF", "ZOFF")) or n.startswith("COMPASS_OFS")],
        }[kind]
        assert len(off) == 3, (kind, fmt, got)
        si = np.array([float(got[n][0]) * UPSTREAM_UNIT[(ap[n][0] if fmt == "ardupilot" else px4[n][1])] for n in off])
        want = {
            "accel": np.array([0.1, -0.2, 0.3]) / -np.array([1.01, 0.99, 1.0]),  # B = -o s -> o = -B / s
            "gyro": np.array([0.01, -0.02, 0.03]),
            # PX4 subtracts CAL_MAG_OFF = h; ArduPilot ADDS COMPASS_OFS = -h (uT -> nT)
            "mag": np.array([10.0, -5.0, 2.0]) * 1e3 * (-1 if fmt == "ardupilot" else 1),
        }[kind]
        assert np.allclose(si, want, rtol=1e-6), (kind, fmt, inst, dict(zip(off, si)), want)


def test_the_instances_the_export_takes_are_the_firmwares_slots(capsys, tmp_path):
    """PX4 defines CAL_*${i} for i = 0..3 (module.yaml num_instances 4, instance_start 0);
    ArduPilot INS_ACC{,2,3}, INS_GYR{,2,3}, COMPASS_OFS{,2,3} (the var_info above): the export
    takes exactly those, and one more is refused in one line, exit 2, nothing on stdout."""
    px4, ap = px4_definitions(), ardupilot_definitions()
    px4_slots = {int(re.match(r"CAL_ACC(\d+)_ID$", n)[1]) for n in px4 if re.match(r"CAL_ACC\d+_ID$", n)}
    ap_slots = {int(m[1] or 1) for n in ap if (m := re.match(r"COMPASS_OFS(\d?)_X$", n))}
    assert px4_slots == {0, 1, 2, 3} and ap_slots == {1, 2, 3}
    db = str(tmp_path / "s.db")
    m, cols = small_capture(procedure="compass", mag_unit="uT", sensor_device_id="197388")
    with Store(db) as s:
        cid = s.save_calibration(compass_result(device="M", soft_iron=(1e3 * np.eye(3)).tolist()), meta=m, columns=cols)
    for fmt, slots in (("ardupilot", ap_slots), ("px4", px4_slots), ("qgc", px4_slots)):
        for inst in sorted(slots) + [max(slots) + 1, min(slots) - 1]:
            code, text, err = run(capsys, "export", cid, "--format", fmt, "--instance", inst, "--db", db)
            if inst in slots:
                assert code == 0, (fmt, inst, err)
            else:
                assert code == 2 and text == "" and err.count("\n") == 1, (fmt, inst, text, err)


def test_the_bounds_the_export_checks_are_the_documented_ones():
    """The constants station/firmware_export.py checks against, compared with the definitions:
    ArduPilot INS_ACCOFFS @Range -3.5 3.5 and INS_ACCSCAL @Range 0.8 1.2; PX4 CAL_ACC/MAG SCALE
    min 0.1, max 3.0; PX4's PRIO -1..100 and ROT -1..40 (accel, gyro), -1..100 (mag)."""
    from station import firmware_export as fx

    px4, ap = px4_definitions(), ardupilot_definitions()
    for n in ("INS_ACCOFFS_X", "INS_ACC2OFFS_Y", "INS_ACC3OFFS_Z"):
        assert (ap[n][1], ap[n][2]) == (-fx.AP_ACC_OFFS_MAX_MPS2, fx.AP_ACC_OFFS_MAX_MPS2), n
    for n in ("INS_ACCSCAL_X", "INS_ACC2SCAL_Y", "INS_ACC3SCAL_Z"):
        assert (ap[n][1], ap[n][2]) == fx.AP_ACC_SCALE_RANGE, n
    for n in ("CAL_ACC0_XSCALE", "CAL_ACC3_ZSCALE", "CAL_MAG0_YSCALE", "CAL_MAG3_ZSCALE"):
        assert px4[n][2:] == fx.PX4_SCALE_RANGE, n
    assert px4["CAL_ACC0_ROT"][2:] == px4["CAL_GYRO3_ROT"][2:] == (-1.0, 40.0)
    assert px4["CAL_MAG0_ROT"][2:] == (-1.0, 100.0)
