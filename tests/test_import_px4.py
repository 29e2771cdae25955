"""`station import` of real PX4 logs (../shared/data/px4_ulog: PX4's own pyulog test logs, written
by PX4 firmware on a CubeOrange, an AUAV-X21 and in SITL), checked against pyulog's reading of
the same files and against physics (|g| at rest, the Earth's field in gauss)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from pyulog import ULog

from station.capture import read_capture
from tests.station_run import run_station

LOGS = (
    "sample.ulg",
    "sample_log_small.ulg",
    "sample_logging_tagged_and_default_params.ulg",
    "sample_px4_events.ulg",
)


@pytest.fixture(scope="module")
def px4_dir(shared_data):
    return shared_data / "px4_ulog" / "original"


def _topic(ulog, name, multi_id=0):
    return next(d for d in ulog.data_list if d.name == name and d.multi_id == multi_id).data


def _import(tmp_path, log, *args):
    out = tmp_path / (log.stem + ".capture.csv")
    res = run_station("import", log, "--out", out, *args)
    assert res.returncode == 0, res.stderr
    assert res.stdout.count("\n") == 1 and str(out) in res.stdout
    return read_capture(out), res


@pytest.mark.parametrize("name", LOGS)
def test_every_log_imports_with_its_cal_parameters(tmp_path, px4_dir, name):
    log = px4_dir / name
    capture, _ = _import(tmp_path, log, "--procedure", "accel-tabletop")
    ulog = ULog(str(log))
    meta = capture.meta
    assert meta["procedure"] == "accel-tabletop" and meta["firmware"] == "px4"
    cal = {k: v for k, v in ulog.initial_parameters.items() if k.startswith("CAL_")}
    assert len(cal) > 50
    for (
        key,
        value,
    ) in cal.items():  # the value the firmware stores (float32 or int32), to the bit
        text = meta[f"param.{key}"]
        if isinstance(value, int):
            assert int(text) == value, key
        else:
            assert np.float32(float(text)) == np.float32(value), key
    assert meta["accel_unit"] == "m/s^2" and meta["gyro_unit"] == "rad/s"
    t = capture.columns["t"]
    assert t[0] == 0 and np.all(np.diff(t) >= 0)


def test_raw_topics_are_uncorrected_and_carry_their_device_and_cal_slot(tmp_path, px4_dir):
    """CubeOrange, PX4 v1.11: sensor_accel is the driver's output (PX4 applies CAL_ACCn later)."""
    log = px4_dir / "sample_log_small.ulg"
    capture, res = _import(tmp_path, log, "--procedure", "accel-tabletop")
    ulog = ULog(str(log))
    acc = _topic(ulog, "sensor_accel", 0)
    meta = capture.meta
    assert meta["corrected"] == "false"
    assert int(meta["sensor_device_id"]) == int(acc["device_id"][0]) == 2424842
    slot = int(meta["sensor_instance"])
    assert ulog.initial_parameters[f"CAL_ACC{slot}_ID"] == int(acc["device_id"][0])
    # rows are sensor_accel's own samples (float32 values, exactly), t from timestamp_sample
    n = capture.n_rows
    ax = np.asarray(acc["x"], dtype=np.float64)
    start = int(np.flatnonzero(ax == capture.columns["ax"][0])[0])
    np.testing.assert_array_equal(capture.columns["ax"], ax[start : start + n])
    ts = np.asarray(acc["timestamp_sample"], dtype=np.int64)[start : start + n]
    np.testing.assert_allclose(capture.columns["t"], (ts - ts[0]) * 1e-6, atol=1e-9)
    # physics: the board stood on the ground: |f| ≈ g in m/s², |B| of the Earth in gauss
    f = np.linalg.norm(np.column_stack([capture.columns[c] for c in ("ax", "ay", "az")]), axis=1)
    assert abs(np.median(f) - 9.81) < 0.3
    b = np.linalg.norm(np.column_stack([capture.columns[c] for c in ("mx", "my", "mz")]), axis=1)
    assert 0.2 < np.median(b) < 0.7
    # the raw topics were logged at 1 Hz: the importer says where the dense data are
    assert "--source combined" in res.stderr


def test_instance_option_picks_the_second_imu(tmp_path, px4_dir):
    log = px4_dir / "sample_log_small.ulg"
    capture, _ = _import(tmp_path, log, "--procedure", "gyro-drift", "--instance", "1")
    ulog = ULog(str(log))
    gyro1 = _topic(ulog, "sensor_gyro", 1)
    assert int(capture.meta["sensor_device_id"]) == int(gyro1["device_id"][0]) == 3670050
    assert capture.meta["sensor_instance"] == "1"  # CAL_GYRO1_ID = 3670050
    assert set(capture.columns["gx"]) <= set(np.asarray(gyro1["x"], dtype=np.float64))


def test_sensor_combined_is_marked_corrected(tmp_path, px4_dir):
    """The AUAV-X21 log predates sensor_accel: sensor_combined, after CAL_* and SENS_BOARD_ROT."""
    capture, _ = _import(tmp_path, px4_dir / "sample.ulg", "--procedure", "compass")
    meta = capture.meta
    assert meta["corrected"] == "true" and meta["mag_unit"] == "gauss"
    assert "sensor_combined" in meta["import_source"]
    # one row per magnetometer sample at its own time: the topic, stamped by the 250 Hz gyro,
    # repeats the ~96 Hz magnetometer's newest sample until the next one (17,070 rows)
    sc = _topic(ULog(str(px4_dir / "sample.ulg"), ["sensor_combined"]), "sensor_combined")
    t_mag = np.asarray(sc["timestamp"], np.int64) + np.asarray(sc["magnetometer_timestamp_relative"], np.int64)
    samples = len(np.unique(t_mag))
    assert samples < 7000 and samples - 2 <= capture.n_rows <= samples
    assert abs(float(meta["sample_rate_hz"]) - 96.5) < 1
    assert "magnetometer_ga, each sample once at its own time" in meta["import_source"]
    b = np.linalg.norm(np.column_stack([capture.columns[c] for c in ("mx", "my", "mz")]), axis=1)
    assert 0.2 < np.nanmedian(b) < 0.7  # the Earth's field, in gauss
    combined, _ = _import(
        tmp_path,
        px4_dir / "sample_log_small.ulg",
        "--procedure",
        "accel-tabletop",
        "--source",
        "combined",
    )
    assert combined.meta["corrected"] == "true" and combined.n_rows > 1000


def test_calibrate_and_diagnose_read_the_log_directly(tmp_path, px4_dir):
    log = px4_dir / "sample.ulg"
    res = run_station("calibrate", log)
    assert res.returncode == 2 and res.stdout == ""
    assert res.stderr.count("\n") == 1 and "--procedure" in res.stderr and str(log) in res.stderr
    # a flight has no static positions: refused with the reason, one line
    res = run_station("calibrate", log, "--procedure", "accel-tabletop")
    assert res.returncode == 2 and res.stdout == "" and res.stderr.count("\n") == 1
    assert "static positions" in res.stderr
    # the same file through import then calibrate gives the same answer as calibrate on the log
    _import(tmp_path, log, "--procedure", "gyro-drift")
    direct = run_station("calibrate", log, "--procedure", "gyro-drift", "--json")
    via = run_station("calibrate", tmp_path / "sample.capture.csv", "--json")
    assert direct.returncode == via.returncode
    if direct.returncode == 0:
        a, b = json.loads(direct.stdout), json.loads(via.stdout)
        assert a["params"] == b["params"]
    res = run_station("diagnose", log, "--procedure", "gyro-drift", "--json")
    assert res.returncode in (0, 2) and "Traceback" not in res.stderr
    if res.returncode == 2:
        assert res.stderr.count("\n") == 1


@pytest.mark.parametrize(
    "content, says",
    [
        (b"", "empty file"),
        (b"hello, this is not a log\n", "not a PX4 ULog file: it does not start with the ULog header"),
    ],
)
def test_bad_ulog_one_line_and_nothing_written(tmp_path, content, says):
    bad = tmp_path / "flight.ulg"
    bad.write_bytes(content)
    out = tmp_path / "out.csv"
    out.write_text("keep me\n")
    res = run_station("import", bad, "--procedure", "accel-tabletop", "--out", out)
    assert res.returncode == 2 and res.stdout == ""
    assert res.stderr.count("\n") == 1 and f"{bad}: " in res.stderr and says in res.stderr
    assert out.read_text() == "keep me\n"  # nothing half-written
    assert sorted(p.name for p in tmp_path.iterdir()) == ["flight.ulg", "out.csv"]


def test_truncated_real_log_is_refused_or_imported_whole(tmp_path, px4_dir):
    """A log cut mid-file (a crash, a copy stopped early): one line, or the part that is there."""
    data = (px4_dir / "sample_logging_tagged_and_default_params.ulg").read_bytes()
    cut = tmp_path / "cut.ulg"
    cut.write_bytes(data[: len(data) // 3])
    res = run_station("import", cut, "--procedure", "accel-tabletop", "--out", tmp_path / "cut.csv")
    assert "Traceback" not in res.stderr
    if res.returncode == 0:
        read_capture(tmp_path / "cut.csv")
    else:
        assert res.returncode == 2 and res.stderr.count("\n") == 1 and not (tmp_path / "cut.csv").exists()


def test_a_log_cut_inside_a_message_is_imported_with_a_warning_saying_so(tmp_path, px4_dir):
    """pyulog stops without a word where a file ends inside a message: a log cut by a power
    loss imported as a shorter dataset and nothing said it. Now a warning names the byte
    where it is cut and what was imported; the whole log says nothing of the kind."""
    data = (px4_dir / "sample.ulg").read_bytes()
    cut = tmp_path / "cut.ulg"
    cut.write_bytes(data[: len(data) // 3])
    # --instance 0: the log has two gyro slots and no sensor_selection (else a line says so)
    capture, res = _import(tmp_path, cut, "--procedure", "gyro-drift", "--instance", "0")
    # one line of its own (the other, sample.ulg's 31 ms dropout before the cut: the dropouts test)
    assert [w for w in res.stderr.splitlines() if "dropped messages" not in w and "cut short" not in w] == []
    assert res.stderr.count("cut short") == 1, res.stderr
    assert f"cut.ulg: warning: the log is cut short inside a message at byte {len(data) // 3}" in res.stderr
    n = len(capture.columns["t"])
    said = int(res.stderr.split("the samples before it are imported, ")[1].split(" samples up to")[0])
    assert n <= said <= n + 3  # the log's samples; the capture ends where every sensor has one
    whole, res = _import(tmp_path, px4_dir / "sample.ulg", "--procedure", "gyro-drift", "--instance", "0")
    assert "cut short" not in res.stderr
    assert 0 < n < len(whole.columns["t"])
    np.testing.assert_array_equal(capture.columns["gx"], whole.columns["gx"][:n])  # what is there, whole


def test_bad_instance_names_the_ones_there(tmp_path, px4_dir):
    res = run_station(
        "import",
        px4_dir / "sample_log_small.ulg",
        "--procedure",
        "accel-tabletop",
        "--instance",
        "7",
        "--out",
        tmp_path / "x.csv",
    )
    assert res.returncode == 2 and "instances 0, 1, 2" in res.stderr and not (tmp_path / "x.csv").exists()


def test_out_must_not_be_the_log(tmp_path, px4_dir):
    log = tmp_path / "copy.ulg"
    log.write_bytes((px4_dir / "sample_px4_events.ulg").read_bytes())
    res = run_station("import", log, "--procedure", "accel-tabletop", "--out", log)
    assert res.returncode == 2 and "--out is the input file" in res.stderr
    assert log.read_bytes() == (px4_dir / "sample_px4_events.ulg").read_bytes()


def test_combined_compass_from_vehicle_magnetometer_with_place_and_date(tmp_path, px4_dir):
    """PX4 ≥ 1.11 logs the calibrated compass as vehicle_magnetometer; the SITL log's GPS gives
    PX4's default SITL home (47.397742 N, 8.545594 E, Zürich) and the UTC date of the flight."""
    capture, _ = _import(
        tmp_path,
        px4_dir / "sample_px4_events.ulg",
        "--procedure",
        "compass",
        "--source",
        "combined",
    )
    meta = capture.meta
    assert meta["corrected"] == "true" and "vehicle_magnetometer[0]" in meta["import_source"]
    assert abs(float(meta["latitude_deg"]) - 47.397742) < 1e-4 and abs(float(meta["longitude_deg"]) - 8.545594) < 1e-4
    assert meta["date"].startswith("2024-03-18")
    b = np.linalg.norm(np.column_stack([capture.columns[c] for c in ("mx", "my", "mz")]), axis=1)
    assert 0.4 < np.median(b) < 0.55  # Zürich's field, about 0.48 gauss


def test_inspect_shows_what_import_would_write_and_instance_spares_other_sensors(
    px4_dir,
):
    """--instance 2 on a board with two compasses: the gyro-drift capture of IMU 2, no mag columns."""
    res = run_station(
        "inspect",
        px4_dir / "sample_log_small.ulg",
        "--procedure",
        "gyro-drift",
        "--instance",
        "2",
        "--json",
    )
    assert res.returncode == 0, res.stderr
    s = json.loads(res.stdout)
    assert s["metadata"]["sensor_device_id"] == "2621474"  # sensor_gyro[2], CAL_GYRO2_ID
    assert [c["name"] for c in s["columns"] if c["name"].startswith("m")] == []
    assert "no sensor_mag[2]" in res.stderr


def test_an_instance_asked_of_a_log_with_one_combined_stream_is_refused(tmp_path, px4_dir):
    """`--instance 5` on a log that has only sensor_combined (no per-sensor topics) imported
    the board's selected sensor without a word: the bench engineer asked for another IMU.
    Refused naming why; --instance 0 (or none) still reads it."""
    from tests.station_run import assert_one_line_refusal

    out = tmp_path / "o.csv"
    res = run_station("import", px4_dir / "sample.ulg", "--procedure", "gyro-drift", "--out", out, "--instance", "5")
    # no sensor_selection in this log: --instance names the CAL slot of the voter's sensor, and slot 5 is empty
    assert_one_line_refusal(res, "sample.ulg: --instance 5: no CAL_GYRO5_ID in the log (CAL_GYRO0_ID 2162688, ")
    assert not out.exists()
    res = run_station(
        "import",
        px4_dir / "sample_log_small.ulg",
        "--procedure",
        "gyro-drift",
        "--out",
        out,
        "--source",
        "combined",
        "--instance",
        "1",
    )
    assert_one_line_refusal(res, "--instance 1: sensor_combined holds one stream, the board's selected sensor")
    assert not out.exists()
    _import(tmp_path, px4_dir / "sample.ulg", "--procedure", "gyro-drift", "--instance", "0")


@pytest.mark.parametrize("wrong", [".bin", ".tlog", ".BIN"])
def test_a_ulog_under_another_logs_suffix_is_read_as_the_ulog_it_is(tmp_path, px4_dir, wrong):
    """A .ulg copied as .bin (or .tlog) was read by the DataFlash or MAVLink reader: 'no IMU or
    MAG messages in the DataFlash log', the data lost. The ULog header says what it is: the
    same capture as from the .ulg, with a warning naming the mismatch."""
    log = px4_dir / "sample_log_small.ulg"
    renamed = tmp_path / f"flight{wrong}"
    renamed.write_bytes(log.read_bytes())
    want, _ = _import(tmp_path, log, "--procedure", "gyro-drift", "--source", "combined")
    got, res = _import(tmp_path, renamed, "--procedure", "gyro-drift", "--source", "combined")
    assert "a PX4 ULog file" in res.stderr and wrong in res.stderr, res.stderr
    assert got.meta == want.meta and got.columns.keys() == want.columns.keys()
    for k in want.columns:
        np.testing.assert_array_equal(got.columns[k], want.columns[k])


def test_a_dataflash_log_named_ulg_is_read_as_the_dataflash_log_it_is(tmp_path):
    """The other way round: a DataFlash .bin named .ulg was refused by pyulog ('Failed to parse header')."""
    from tests.test_import_ardupilot import write_bin

    write_bin(tmp_path / "a.bin")
    (tmp_path / "a.ulg").write_bytes((tmp_path / "a.bin").read_bytes())
    want, _ = _import(tmp_path, tmp_path / "a.bin", "--procedure", "compass")
    got, res = _import(tmp_path, tmp_path / "a.ulg", "--procedure", "compass")
    assert "an ArduPilot DataFlash log" in res.stderr and ".ulg" in res.stderr, res.stderr
    assert got.meta == want.meta
    for k in want.columns:
        np.testing.assert_array_equal(got.columns[k], want.columns[k])


def test_a_log_without_sensor_selection_says_which_sensors_the_voter_chose_from(tmp_path, px4_dir):
    """sample.ulg (AUAV-X21, PX4 before v1.10) has sensor_combined and no sensor_selection: the
    sensors module's voter (VotedSensorsUpdate, DataValidatorGroup::get_best) chose the sensor by
    the drivers' uORB priority and health; no parameter chose it (CAL_*_PRIME is only what the
    preflight check requires present; read in PX4/PX4-Autopilot src/modules/sensors and
    commander). The import named no sensor and the export then took slot 0 without a word. Now:
    two accelerometer slots in use -> one warning line naming both and --instance; --instance 1
    names slot 1; one magnetometer slot -> its device id."""
    cap, res = _import(tmp_path, px4_dir / "sample.ulg", "--procedure", "accel-tabletop")
    lines = [w for w in res.stderr.splitlines() if "voter" in w]
    assert len(lines) == 1, res.stderr
    assert "CAL_ACC0_ID 1245450 or CAL_ACC1_ID 1441792" in lines[0] and "--instance N" in lines[0]
    assert "CAL_ACC_PRIME 1245450 is the calibration's primary" in lines[0]
    assert "accel_device_id" not in cap.meta and "sensor_device_id" not in cap.meta
    cap, res = _import(tmp_path, px4_dir / "sample.ulg", "--procedure", "accel-tabletop", "--instance", "1")
    assert "voter" not in res.stderr
    assert cap.meta["accel_device_id"] == "1441792" and cap.meta["sensor_instance"] == "1"
    cap, res = _import(tmp_path, px4_dir / "sample.ulg", "--procedure", "compass")
    assert "voter" not in res.stderr and cap.meta["mag_device_id"] == "262144"  # CAL_MAG0_ID, the only one


@pytest.mark.parametrize("name", LOGS)
def test_the_loggers_own_dropouts_are_said(tmp_path, px4_dir, name):
    """PX4's logger writes a dropout message ('O', duration in ms) where its buffer overflowed and
    messages were lost. sample.ulg (AUAV-X21) has four, two of them (31 ms, 62 ms) while the
    samples run: the import kept the gaps in the time axis and said nothing of them (a 64 ms
    hole in a 250 Hz record looked like any other stretch). Now one warning with their number,
    total and longest, as pyulog reads them; a log without any inside its samples says none."""
    log = px4_dir / name
    capture, res = _import(tmp_path, log, "--procedure", "gyro-drift", "--source", "combined")
    u = ULog(str(log), ["sensor_combined"])
    t = _topic(u, "sensor_combined")["timestamp"]
    lost = [d.duration for d in u.dropouts if d.duration > 0 and t[0] <= d.timestamp <= t[-1]]
    said = [w for w in res.stderr.splitlines() if "the logger dropped messages" in w]
    if not lost:
        assert not said, res.stderr
        return
    n = len(lost)
    assert said and f"dropped messages {n} time{'s' if n != 1 else ''}" in said[0], res.stderr
    assert f"({sum(lost)} ms in all, the longest {max(lost)} ms" in said[0], res.stderr
    # and each one is a gap in the capture's time axis right after the sample it is stamped with
    tc = np.asarray(capture.columns["t"])
    for d in u.dropouts:
        if d.duration > 0 and t[0] <= d.timestamp <= t[-1]:
            at = (d.timestamp - t[0]) * 1e-6
            i = np.searchsorted(tc, at + 1e-9)
            assert tc[i] - tc[i - 1] >= d.duration * 1e-3, (at, tc[i - 1 : i + 1])


V5 = Path(__file__).resolve().parent / "data" / "px4_fmu_v5_robologs" / "test_sensors.ulg"


def test_a_selection_that_changes_while_the_samples_run_is_said(tmp_path):
    """A Pixhawk 5 log (tests/data/px4_fmu_v5_robologs, SOURCE.md there) whose sensor_selection
    switches sensor_combined's accel from 4259850 to 3932170 (and back, and again) 2.4 s into the
    samples: the import wrote a capture naming no sensor and said nothing (the export then asked
    which accel it was). The data mix two IMUs: now a warning says which, from when, as the
    log's own sensor_selection (read by pyulog) has them."""
    u = ULog(str(V5), ["sensor_selection", "sensor_combined"])
    t = _topic(u, "sensor_combined")["timestamp"]
    sel = _topic(u, "sensor_selection")
    ts, ids = sel["timestamp"], sel["accel_device_id"]
    start = max(int(np.searchsorted(ts, t[0], side="right")) - 1, 0)
    in_effect = [int(i) for i, tt in zip(ids[start:], ts[start:]) if tt <= t[-1]]
    assert len(set(in_effect)) == 2  # the log as it is
    capture, res = _import(tmp_path, V5, "--procedure", "accel-tabletop", "--source", "combined")
    assert "accel_device_id" not in capture.meta
    said = [w for w in res.stderr.splitlines() if "came from 2 sensors while the samples run" in w]
    assert len(said) == 1 and "sensor_combined's accel" in said[0], res.stderr
    assert f"{in_effect[0]} from the start, {in_effect[1]} from {(ts[start + 1] - t[0]) * 1e-6:.3f} s" in said[0]


def test_a_selection_that_changed_before_the_samples_names_the_one_in_effect(tmp_path):
    """The same log, its sensor_combined cut by pyulog's own writer to the samples after the last
    change (3932170 from 5.715 s of boot): every sample is from CAL_ACC2's sensor, but the import
    took the selection's records before the samples too, found two ids and named none, so the
    export refused ("which accel the data came from is unknown"). Now the id in effect, and the
    export writes CAL_ACC2 with it."""
    u = ULog(str(V5))
    sel = _topic(u, "sensor_selection")
    last = int(sel["timestamp"][-1])
    for d in u.data_list:
        if d.name == "sensor_combined":
            keep = d.data["timestamp"] > last + 50_000
            d.data = {k: v[keep] for k, v in d.data.items()}
    cut = tmp_path / "after_switch.ulg"
    u.write_ulog(str(cut))
    want = int(sel["accel_device_id"][-1])
    assert want == int(u.initial_parameters["CAL_ACC2_ID"]) == 3932170  # the log as it is
    capture, res = _import(tmp_path, cut, "--procedure", "accel-tabletop", "--source", "combined")
    assert capture.meta["accel_device_id"] == str(want), capture.meta
    assert "sensors while the samples run" not in res.stderr
    db = tmp_path / "s.db"
    cal = run_station("calibrate", tmp_path / "after_switch.capture.csv", "--json", "--save", "--db", db)
    if cal.returncode != 0:  # a ground log has one pose: the export is checked on a stored fit
        from db_testdata import accel_result

        from db import Store

        with Store(str(db)) as s:
            cid = s.save_calibration(
                accel_result(device=capture.meta["device"]), meta=capture.meta, columns=capture.columns
            )
    else:
        cid = json.loads(cal.stdout)["calibration_id"]
    res = run_station("export", cid, "--format", "px4", "--db", db)
    assert res.returncode == 0, res.stderr
    assert f"param set CAL_ACC2_ID {want}" in res.stdout, res.stdout
