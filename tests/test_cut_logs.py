"""Real flight logs cut short (a power loss while logging, a copy stopped part-way) given to
the commands that read them: where what is left cannot be calibrated, the one refusal line says
the log was cut and where, not only what the cut left ("no IMU data", "only 1 accelerometer
sample"), which sends the operator looking for a wrong topic or a wrong procedure; the database
given with --save gets no row. An outside tester's findings (branch qa-s24b)."""

from __future__ import annotations

import sqlite3

import pytest

from tests.station_run import assert_one_line_refusal, run_station

SMALL_ULG = "px4_ulog/original/sample_log_small.ulg"
# byte offsets inside sample_log_small.ulg (921,631 bytes): 1,325 is inside its definitions
# (format and parameter messages), 220,080 inside a data message after the first raw
# sensor_accel sample, 357,876 inside one after the second (the other sensors have not all
# begun by then)
CUTS = {
    1325: "no IMU data",
    220080: "only 1 accelerometer sample",
    357876: "fewer than 2 accelerometer samples where all sensors overlap",
}


def _rows(db) -> dict[str, int]:
    with sqlite3.connect(db) as con:
        tables = [r[0] for r in con.execute("select name from sqlite_master where type = 'table'")]
        return {t: con.execute(f'select count(*) from "{t}"').fetchone()[0] for t in tables}


@pytest.mark.parametrize("cut", sorted(CUTS))
def test_a_ulog_cut_inside_a_message_is_refused_saying_it_was_cut(tmp_path, shared_data, cut):
    data = (shared_data / SMALL_ULG).read_bytes()
    log = tmp_path / "cut.ulg"
    log.write_bytes(data[:cut])
    db = tmp_path / "station.db"
    assert run_station("--db", db, "devices", "add", "BENCH-1").returncode == 0
    before = _rows(db)
    res = run_station(
        "calibrate", log, "--procedure", "accel-tabletop", "--json", "--save", "--db", db, subprocess_run=True
    )
    assert "Traceback" not in res.stderr
    assert_one_line_refusal(res, f"{log}: ", CUTS[cut], f"cut short inside a message at byte {cut}")
    assert _rows(db) == before


@pytest.mark.parametrize("command", ["import", "diagnose"])
def test_the_other_commands_say_the_cut_in_their_refusal_too(tmp_path, shared_data, command):
    log = tmp_path / "cut.ulg"
    log.write_bytes((shared_data / SMALL_ULG).read_bytes()[:220080])
    out = tmp_path / "out.csv"
    args = ("--out", out) if command == "import" else ("--json",)
    res = run_station(command, log, "--procedure", "accel-tabletop", *args)
    assert_one_line_refusal(res, f"{log}: ", "cut short inside a message at byte 220080")
    assert not out.exists()


def test_a_ulog_cut_to_one_sample_says_one_sample(tmp_path, shared_data):
    """The cut warning counted "1 samples" (and the raw-topic hint "hold 1 samples")."""
    log = tmp_path / "cut.ulg"
    log.write_bytes((shared_data / SMALL_ULG).read_bytes()[:220080])
    res = run_station("import", log, "--procedure", "accel-tabletop", "--out", tmp_path / "out.csv")
    assert_one_line_refusal(
        res, "the raw sensor topics hold 1 sample, ", "the samples before it are imported, 1 sample up to 0.015202 s"
    )
    assert "1 samples" not in res.stderr


@pytest.mark.parametrize("n", [1, 4, 7, 8, 15])
def test_a_ulog_cut_inside_its_header_is_refused_in_the_stations_words(tmp_path, shared_data, n):
    """A ULog cut inside its 16-byte file header (magic, version, start time) was refused with
    pyulog's words: `not a readable PX4 ULog file (ULogException: Invalid file format (Header too
    short))`. Now the station's own line says it was cut, and where."""
    log = tmp_path / "cut.ulg"
    log.write_bytes((shared_data / SMALL_ULG).read_bytes()[:n])
    db = tmp_path / "station.db"
    assert run_station("--db", db, "devices", "add", "BENCH-1").returncode == 0
    before = _rows(db)
    res = run_station(
        "calibrate", log, "--procedure", "accel-tabletop", "--json", "--save", "--db", db, subprocess_run=True
    )
    bytes_ = "byte" if n == 1 else "bytes"
    assert_one_line_refusal(
        res, f"{log}: a PX4 ULog cut short inside its 16-byte header ({n} {bytes_} in the file): nothing to read"
    )
    assert "ULogException" not in res.stderr and "Header too short" not in res.stderr
    assert _rows(db) == before


@pytest.mark.parametrize("content", [b"hello, this is not a log\n", b"ULog\x02", b"xyz"])
def test_a_file_named_ulg_that_is_no_ulog_says_so_in_the_stations_words(tmp_path, content):
    """Not pyulog's 'Invalid file format (Failed to parse header)': what the file starts with."""
    log = tmp_path / "flight.ulg"
    log.write_bytes(content)
    res = run_station("import", log, "--procedure", "accel-tabletop", "--out", tmp_path / "o.csv")
    assert_one_line_refusal(res, f"{log}: not a PX4 ULog file: it does not start with the ULog header (ULog 01 12 35")
    assert "ULogException" not in res.stderr
    assert not (tmp_path / "o.csv").exists()


def test_a_ulog_that_ends_between_two_messages_says_no_cut(tmp_path, shared_data):
    """The whole log, and the log cut where one message ends and the next begins, import
    without a word about a cut: nothing in them is cut."""
    log = shared_data / SMALL_ULG
    res = run_station("import", log, "--procedure", "accel-tabletop", "--out", tmp_path / "whole.csv")
    assert res.returncode == 0, res.stderr
    assert "cut short" not in res.stderr


# --- ArduPilot DataFlash -------------------------------------------------------------------------

# pymavlink's own test log (tests/data/ardupilot_pymavlink/SOURCE.md): its MAG records (34 bytes)
# start at bytes 27,755 and 44,670, its IMU records (53 bytes) at 15,561, 19,460, 23,565, ...;
# a record ends exactly at byte 20,000 and the next one's header starts there
TEST_BIN = "tests/data/ardupilot_pymavlink/test.BIN"


def _cut_bin(tmp_path, n: int):
    from tests.station_run import ROOT

    log = tmp_path / "cut.BIN"
    log.write_bytes((ROOT / TEST_BIN).read_bytes()[:n])
    return log


def test_a_dataflash_log_cut_inside_a_record_is_imported_with_a_warning(tmp_path):
    """Before: the IMU record cut by the end of the file was left out without a word."""
    log = _cut_bin(tmp_path, 23565 + 20)
    res = run_station("import", log, "--procedure", "accel-tabletop", "--out", tmp_path / "out.csv")
    assert res.returncode == 0, res.stderr
    assert "warning: the log is cut short inside a record (IMU) at byte 23565 (20 of its 53 bytes there)" in (
        res.stderr
    )


@pytest.mark.parametrize(
    ("n", "says"),
    [
        (20002, "cut short inside a record's header at byte 20000 (2 of its 3 bytes there)"),
        # the whole header there: pymavlink does not index it, its type byte names it
        (20003, "cut short inside a record (PARM) at byte 20000 (3 of its 31 bytes there)"),
    ],
)
def test_a_dataflash_log_cut_inside_a_records_header_is_imported_with_a_warning(tmp_path, n, says):
    log = _cut_bin(tmp_path, n)
    res = run_station("import", log, "--procedure", "accel-tabletop", "--out", tmp_path / "out.csv")
    assert res.returncode == 0, res.stderr
    assert says in res.stderr


def test_a_dataflash_log_that_ends_where_a_record_ends_says_no_cut(tmp_path):
    res = run_station("import", _cut_bin(tmp_path, 20000), "--procedure", "accel-tabletop", "--out", tmp_path / "o.csv")
    assert res.returncode == 0, res.stderr
    assert "cut short" not in res.stderr


def test_a_dataflash_log_cut_to_one_compass_sample_is_refused_saying_it_was_cut(tmp_path):
    log = _cut_bin(tmp_path, 44670 + 10)
    db = tmp_path / "station.db"
    assert run_station("--db", db, "devices", "add", "BENCH-1").returncode == 0
    before = _rows(db)
    res = run_station("calibrate", log, "--procedure", "compass", "--json", "--save", "--db", db, subprocess_run=True)
    assert "Traceback" not in res.stderr
    assert_one_line_refusal(
        res, f"{log}: ", "only 1 magnetometer sample", "cut short inside a record (MAG) at byte 44670 (10 of its 34"
    )
    assert _rows(db) == before


# --- MAVLink telemetry log -----------------------------------------------------------------------


def _tlog_cut_in_a_new_message(tmp_path):
    """A telemetry log (written by pymavlink, tests/test_import_ardupilot.write_tlog) whose
    recording stopped inside a STATUSTEXT, the first of its kind in the log, and the byte where
    that record starts."""
    import struct

    from pymavlink import mavutil

    from tests.test_import_ardupilot import write_tlog

    log = tmp_path / "flight.tlog"
    write_tlog(log)
    whole = log.read_bytes()
    mav = mavutil.mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    frame = mav.statustext_encode(6, b"EKF3 IMU0 is using GPS").pack(mav)
    record = struct.pack(">Q", 1_700_000_003_000_000) + frame
    log.write_bytes(whole + record[: len(record) // 2])
    return log, len(whole)


def test_a_tlog_cut_inside_the_first_message_of_its_kind_is_read_up_to_it(tmp_path):
    """Before: pymavlink reads the first record of each type while it indexes, met the cut one
    and the whole log was refused as 'not a readable MAVLink log (AttributeError: 'NoneType'
    object has no attribute '_instance_field')', its 100 RAW_IMU samples with it."""
    log, at = _tlog_cut_in_a_new_message(tmp_path)
    out = tmp_path / "imu.csv"
    res = run_station("import", log, "--procedure", "accel-tabletop", "--out", out)
    assert res.returncode == 0, res.stderr
    assert res.stdout.startswith(f"{out}: accel-tabletop, 100 rows"), res.stdout
    assert f"warning: the log is cut short inside a message at byte {at}: the messages before it" in res.stderr
    assert "hold no readable message" not in res.stderr  # a cut, not a corrupt stretch


def test_a_tlog_cut_inside_its_first_record_is_refused_saying_it_was_cut(tmp_path):
    """Before: the same AttributeError line, for a log cut 20 bytes in (inside its first
    HEARTBEAT record: 8 bytes of time, then the frame)."""
    from tests.test_import_ardupilot import write_tlog

    log = tmp_path / "flight.tlog"
    write_tlog(log)
    log.write_bytes(log.read_bytes()[:20])
    res = run_station("import", log, "--procedure", "accel-tabletop", "--out", tmp_path / "o.csv")
    assert_one_line_refusal(res, f"{log}: ", "no RAW_IMU", "cut short inside a message at byte 0")
    assert "AttributeError" not in res.stderr


def test_a_file_that_is_no_tlog_read_as_one_is_not_called_cut(shared_data, tmp_path):
    """A ULog given with --format tlog is garbage to the MAVLink walker to its last byte: that
    end is no message cut short, and the refusal does not say it is. In a subprocess: pymavlink
    meeting a 0xFD byte switches the whole process to MAVLink 2 (os.environ['MAVLINK20'], its
    dialect reloaded), which would change what later tests' write_tlog writes."""
    log = shared_data / SMALL_ULG
    res = run_station(
        "import", log, "--format", "tlog", "--procedure", "gyro-drift", "--out", tmp_path / "o.csv", subprocess_run=True
    )
    assert_one_line_refusal(res, f"{log}: ", "no RAW_IMU")
    assert "cut short" not in res.stderr


def test_reading_a_mavlink2_tlog_leaves_the_process_on_its_mavlink_version(tmp_path):
    """pymavlink, meeting a MAVLink 2 frame in a log, sets os.environ['MAVLINK20'] and reloads
    its dialect for the whole process: afterwards every MAVLink object the process makes (the
    TUI's live link, a later import's checks, a test's writer) speaks MAVLink 2. Reading a log is
    no reason to change that: the import leaves both as they were."""
    import os
    import struct

    from pymavlink import mavutil
    from pymavlink.dialects.v20 import ardupilotmega as v2

    mav = v2.MAVLink(None, srcSystem=1, srcComponent=1)
    records = []
    for k in range(50):
        t_us = 1_700_000_000_000_000 + k * 20_000
        frame = mav.raw_imu_encode(1_000_000 + k * 20_000, 10, -20, -1000, 5, -6, 7, 200, -100, 400).pack(mav)
        records.append(struct.pack(">Q", t_us) + frame)
    log = tmp_path / "v2.tlog"
    log.write_bytes(b"".join(records))
    before = (os.environ.get("MAVLINK20"), mavutil.mavlink, mavutil.mavlink.WIRE_PROTOCOL_VERSION)
    res = run_station("import", log, "--procedure", "gyro-drift", "--out", tmp_path / "o.csv")
    after = (os.environ.get("MAVLINK20"), mavutil.mavlink, mavutil.mavlink.WIRE_PROTOCOL_VERSION)
    try:
        assert res.returncode == 0, res.stderr
        assert res.stdout.startswith(f"{tmp_path / 'o.csv'}: gyro-drift, 50 rows"), res.stdout
        assert after == before
    finally:  # never leave the process switched for the tests after this one
        if after != before:
            if before[0] is None:
                os.environ.pop("MAVLINK20", None)
            else:
                os.environ["MAVLINK20"] = before[0]
            mavutil.mavlink = before[1]


# ------------------------------------------------------------------ ULogs without IMU data
# written by pyulog's own writer (ULog.write_ulog) from the shared logs, the data sections left
# out where a test says so: header, definitions and parameters exactly as pyulog writes them


def _rewrite(src, dest, keep) -> object:
    """``src`` written again by pyulog with only the data sets ``keep(name)`` keeps."""
    from pyulog import ULog

    ulog = ULog(str(src))
    ulog._data_list = [d for d in ulog.data_list if keep(d.name)]  # pyulog keeps no public setter
    ulog.write_ulog(str(dest))
    return ULog(str(dest))


@pytest.mark.parametrize("source", ["auto", "raw", "combined"])
def test_a_header_only_ulog_says_it_holds_no_data_messages(tmp_path, shared_data, source):
    """A valid ULog that holds its header, formats and parameters but no data message (the
    logger stopped before any) was refused "no IMU data: the log has neither sensor_accel/...
    nor sensor_combined", naming topics its formats do define, as if the wrong ones were logged."""
    log = tmp_path / "header_only.ulg"
    back = _rewrite(shared_data / SMALL_ULG, log, lambda _name: False)
    assert back.data_list == [] and not back.file_corruption
    want = (
        f"{log}: no IMU data: the log holds no data messages, only its header ({len(back.message_formats)} "
        f"topic formats, {len(back.initial_parameters)} parameters): no topic was logged"
    )
    for command, args in (("import", ("--out", tmp_path / "o.csv")), ("calibrate", ())):
        res = run_station(
            command, log, "--procedure", "accel-tabletop", "--source", source, *args, subprocess_run=command == "import"
        )
        assert "Traceback" not in res.stderr
        assert_one_line_refusal(res, want)
    assert not (tmp_path / "o.csv").exists()


def test_a_ulog_without_imu_topics_names_the_topics_it_has(tmp_path, shared_data):
    log = tmp_path / "no_imu.ulg"
    back = _rewrite(shared_data / "px4_ulog/original/sample.ulg", log, lambda name: name != "sensor_combined")
    topics = sorted({d.name for d in back.data_list})
    assert len(topics) == 14
    res = run_station("import", log, "--procedure", "accel-tabletop", "--out", tmp_path / "o.csv")
    assert_one_line_refusal(
        res,
        f"{log}: no IMU data: the log has neither sensor_accel/sensor_gyro/sensor_mag nor sensor_combined; "
        f"its 14 logged topics: {', '.join(topics[:6])} (+8 more)",
    )


def test_combined_asked_of_a_log_with_only_raw_topics_says_raw(tmp_path, shared_data):
    """--source combined of a log with sensor_accel/gyro/mag but no sensor_combined said the log
    had neither: it has the raw ones, and the refusal says so and how to read them."""
    log = tmp_path / "raw_only.ulg"
    _rewrite(shared_data / SMALL_ULG, log, lambda name: name != "sensor_combined")
    res = run_station("import", log, "--procedure", "accel-tabletop", "--source", "combined", "--out", tmp_path / "o")
    assert_one_line_refusal(
        res,
        f"{log}: --source combined: the log has no sensor_combined, only the raw topics "
        "sensor_accel/sensor_gyro/sensor_mag (--source raw, or 'raw topics' on the import screen)",
    )
    assert run_station("import", log, "--procedure", "accel-tabletop", "--out", tmp_path / "o.csv").returncode == 0
