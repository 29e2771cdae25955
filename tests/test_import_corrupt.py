"""Corrupted logs (a crash mid-write, a bad SD card, a copy cut short): every reader refuses
with one line or imports what is readable, and prints nothing but the result on stdout and
nothing but its warnings on stderr, even from pymavlink's compiled indexer, which writes to the
file descriptors directly (checked in a real subprocess)."""

from __future__ import annotations

import numpy as np
import pytest

from station.capture import read_capture
from tests.station_run import ROOT, run_station
from tests.test_import_ardupilot import write_bin, write_tlog


def _mutations(data: bytes, seed: int):
    rng = np.random.default_rng(seed)
    flipped = bytearray(data)
    for j in rng.integers(0, len(data), 40):
        flipped[j] = int(rng.integers(0, 256))
    cut = data[: int(rng.integers(len(data) // 4, len(data)))]
    hole = bytearray(data)
    j = int(rng.integers(0, len(data) - 300))
    hole[j : j + 300] = rng.integers(0, 256, 300, dtype=np.uint8).tobytes()
    mid = len(data) // 2  # a block of zeros inside (a DataFlash page that was never written)
    gap = data[:mid] + bytes(600) + data[mid:]
    return {"flipped": bytes(flipped), "cut": cut, "hole": bytes(hole), "gap": gap}


@pytest.fixture(scope="module")
def sources(tmp_path_factory, shared_data):
    d = tmp_path_factory.mktemp("src")
    write_bin(d / "a.bin")
    write_tlog(d / "a.tlog")
    ulg = shared_data / "px4_ulog" / "original" / "sample_logging_tagged_and_default_params.ulg"
    return {
        ".bin": (d / "a.bin").read_bytes(),
        ".tlog": (d / "a.tlog").read_bytes(),
        ".ulg": ulg.read_bytes(),
    }


@pytest.mark.parametrize("suffix", [".ulg", ".bin", ".tlog"])
@pytest.mark.parametrize("kind", ["flipped", "cut", "hole", "gap"])
def test_corrupt_log_one_line_or_a_valid_capture(tmp_path, sources, suffix, kind):
    data = _mutations(sources[suffix], seed=len(kind) * 7 + len(suffix))[kind]
    log = tmp_path / f"bad{suffix}"
    log.write_bytes(data)
    out = tmp_path / "out.csv"
    res = run_station(
        "import",
        log,
        "--procedure",
        "accel-tabletop",
        "--out",
        out,
        subprocess_run=True,
    )
    assert "Traceback" not in res.stderr
    if res.returncode == 0:
        assert res.stdout.count("\n") == 1 and res.stdout.startswith(f"{out}: ")
        noise = [line for line in res.stderr.splitlines() if ": warning: " not in line]
        assert noise == []  # no reader chatter ("bad header ..." from pymavlink's compiled indexer)
        read_capture(out)  # what was written is a valid capture
    else:
        assert res.returncode == 2 and res.stdout == "" and not out.exists()
        assert res.stderr.count("\n") == 1 and str(log) in res.stderr


def test_a_ulog_parameter_whose_type_is_corrupt_is_left_out_with_a_warning(tmp_path, shared_data):
    """One flipped byte in a parameter's definition ('float' -> 'flxat') leaves pyulog with the
    value as raw bytes; the import ended in the catch-all ('could not convert string to float').
    The parameter is left out of param.*, named in a warning, and the rest is imported."""
    data = (shared_data / "px4_ulog" / "original" / "sample_log_small.ulg").read_bytes()
    assert data.count(b"float CAL_ACC0_XOFF") == 1
    log = tmp_path / "flipped.ulg"
    log.write_bytes(data.replace(b"float CAL_ACC0_XOFF", b"flxat CAL_ACC0_XOFF"))
    out = tmp_path / "out.csv"
    res = run_station("import", log, "--procedure", "accel-tabletop", "--source", "combined", "--out", out)
    assert res.returncode == 0, res.stderr
    assert res.stdout.count("\n") == 1 and res.stdout.startswith(f"{out}: ")
    assert "CAL_ACC0_XOFF" in res.stderr and "warning" in res.stderr, res.stderr
    meta = read_capture(out).meta
    assert "param.CAL_ACC0_XOFF" not in meta
    assert meta["param.CAL_ACC0_YOFF"] == "-0.043480888"


def test_a_gps_time_that_is_no_calendar_date_leaves_the_date_out_with_a_warning(tmp_path):
    """A flipped byte in the GPS message's TimeUS put the log's start 290 000 years before
    Christ: the import ended in the catch-all ('year -541429 is out of range'). The samples
    are imported without a date, and a warning says why."""
    import struct

    log = tmp_path / "gps.bin"
    write_bin(log)
    data = log.read_bytes()
    gms = struct.pack("<IH", 3000, 2300)  # GPS: TimeUS (Q), I, Status (B B), GMS (I), GWk (H)
    assert data.count(gms) == 1
    i = data.index(gms) - 10
    assert struct.unpack("<Q", data[i : i + 8]) == (525000,)
    log.write_bytes(data[:i] + struct.pack("<Q", 2**63 + 525000) + data[i + 8 :])
    out = tmp_path / "out.csv"
    res = run_station("import", log, "--procedure", "compass", "--out", out)
    assert res.returncode == 0, res.stderr
    assert "warning" in res.stderr and "no calendar date" in res.stderr, res.stderr
    meta = read_capture(out).meta
    assert "date" not in meta and "latitude_deg" in meta


@pytest.mark.parametrize("command", ["import", "inspect"])
def test_a_control_character_in_a_logs_text_is_kept_escaped_not_the_whole_log_refused(tmp_path, shared_data, command):
    """One flipped byte in the ULog's hardware name (ver_hw 'CUBEPILOT_...' -> 'C<LF>BEPILOT_...')
    made the board and device metadata unwritable: import refused the whole log, and
    calibrate, diagnose and inspect named the importer's temporary file (station-import-.../capture.csv).
    The text is kept with the character shown escaped, a warning says so, the samples are read."""
    data = bytearray((shared_data / "px4_ulog" / "original" / "sample_log_small.ulg").read_bytes())
    i = data.index(b"ver_hwCUBEPILOT") + len(b"ver_hw")
    data[i + 1] = 0x0A
    log = tmp_path / "hw.ulg"
    log.write_bytes(bytes(data))
    out = tmp_path / "out.csv"
    args = ["--out", out] if command == "import" else []
    res = run_station(command, log, "--procedure", "gyro-drift", "--source", "combined", *args)
    assert res.returncode == 0, res.stderr
    assert "station-import" not in res.stderr and "control character" in res.stderr, res.stderr
    if command == "import":
        meta = read_capture(out).meta
        assert meta["board"].startswith("C\\nBEPILOT_CUBEORANGE") and meta["device"].startswith("C\\nBEPILOT")


@pytest.mark.parametrize("procedure", ["accel-tabletop", "gyro-drift"])
def test_a_compass_that_died_early_does_not_cut_the_imu_rows(tmp_path, procedure):
    """A 5 s DataFlash log whose compass stops after 0.5 s (a sensor lost in flight): rows were
    kept only where every sensor had data, so 196 of the 2000 IMU samples made the capture, with
    no word. Now every IMU sample is a row, the magnetometer's cells are empty after it stopped,
    and a warning says so; a compass that never overlaps the IMU is left out, not a refusal."""
    from tests.test_import_ardupilot import PARAMS, DataFlashWriter

    rng = np.random.default_rng(400017)
    for stops, says in ((200, "its cells are empty outside that"), (0, "never overlaps")):
        log = tmp_path / f"died{stops}.bin"
        w = DataFlashWriter(log, units=True)
        for name in PARAMS:
            w.param(1000, name, PARAMS[name])
        for k in range(2000):  # IMU at 400 Hz for 5 s
            t = 500_000 + k * 2500
            w.imu(t, 0, rng.normal(0, 0.01, 3), np.array([0.1, -0.2, -9.8]) + rng.normal(0, 0.05, 3))
            if k % 4 == 0 and k < stops:
                w.mag(t + 100, 0, (200, -150, 420))
        if not stops:
            w.mag(500_000 + 2000 * 2500 + 10**6, 0, (200, -150, 420))  # one sample, a second after the IMU
        w.close()
        out = tmp_path / f"out{stops}.csv"
        res = run_station("import", log, "--procedure", procedure, "--out", out)
        assert res.returncode == 0, res.stderr
        assert says in res.stderr
        cap = read_capture(out)
        assert cap.n_rows == 2000
        if stops:
            have = np.isfinite(cap.columns["mx"])
            assert 45 <= have.sum() <= 200 and not have[-1000:].any()
        else:
            assert "mx" not in cap.columns


@pytest.mark.parametrize(
    ("log", "says"),
    [
        ("ardupilot", "4116 bytes of the log in one stretch (the first at byte 30005) hold no readable message"),
        ("px4", "the log holds a corrupt stretch (pyulog skipped it to the next sync marker)"),
    ],
)
def test_a_stretch_of_zeros_inside_a_real_log_is_warned_about_not_skipped_silently(tmp_path, shared_data, log, says):
    """A page of an SD card never written (4 KiB of zeros) inside a real log: the readers skip to
    the next message and the samples there are lost (the pymavlink test log: 37 rows → 36;
    sample.ulg: 17069 → 17016). The import said nothing of it: a silently shortened dataset."""
    real, at = (
        (ROOT / "tests" / "data" / "ardupilot_pymavlink" / "test.BIN", 30000)
        if log == "ardupilot"
        else (shared_data / "px4_ulog" / "original" / "sample.ulg", 228231)
    )
    data = bytearray(real.read_bytes())
    data[at : at + 4096] = bytes(4096)
    bad = tmp_path / f"holed{real.suffix}"
    bad.write_bytes(bytes(data))
    rows = {}
    for name, path in (("clean", real), ("holed", bad)):
        out = tmp_path / f"{name}.csv"
        res = run_station("import", path, "--procedure", "gyro-drift", "--out", out, subprocess_run=True)
        assert res.returncode == 0, res.stderr
        warned = [line for line in res.stderr.splitlines() if says in line]
        assert len(warned) == (1 if name == "holed" else 0), res.stderr
        rows[name] = read_capture(out).n_rows
    assert rows["holed"] < rows["clean"]


@pytest.mark.parametrize("damage", ["zeros", "garbage"])
def test_a_corrupt_stretch_inside_a_tlog_is_warned_about_with_its_bytes_and_place(tmp_path, damage):
    """pymavlink's tlog reader steps over bytes where no frame starts and drops a frame whose
    checksum fails, and says nothing: 4 KiB of zeros (or 300 random bytes, with false 0xFE/0xFD
    starts in them) inside a log lost 98 (8) of its 2000 RAW_IMU samples silently. The import
    now says how many bytes hold no readable message and where the stretch begins, as for
    DataFlash and ULog; the rest is imported. The bytes it counts are exactly the records lost."""
    import re

    clean = tmp_path / "clean.tlog"
    write_tlog(clean, n=2000)  # pymavlink's own writer: RAW_IMU frames of 42 bytes with their time
    data = bytearray(clean.read_bytes())
    at = len(data) // 2
    size = 4096 if damage == "zeros" else 300
    rng = np.random.default_rng(400202)
    data[at : at + size] = bytes(size) if damage == "zeros" else rng.integers(0, 256, size, dtype=np.uint8).tobytes()
    holed = tmp_path / "holed.tlog"
    holed.write_bytes(bytes(data))
    rows, said = {}, {}
    for name, path in (("clean", clean), ("holed", holed)):
        out = tmp_path / f"{name}.csv"
        res = run_station("import", path, "--procedure", "accel-tabletop", "--out", out, subprocess_run=True)
        assert res.returncode == 0, res.stderr
        said[name] = [line for line in res.stderr.splitlines() if "hold no readable message" in line]
        rows[name] = read_capture(out).n_rows
    assert said["clean"] == [] and rows["clean"] == 2000
    [line] = said["holed"]
    m = re.search(r"(\d+) bytes of the log in one stretch \(the first at byte (\d+)\)", line)
    assert m, line
    counted, first = int(m.group(1)), int(m.group(2))
    record = 8 + 6 + 26 + 2  # time, MAVLink 1 header, RAW_IMU payload, checksum
    assert first <= at < first + record  # the record the damage begins in
    assert first + counted >= at + size  # to the end of the damage
    assert 0 < rows["holed"] < rows["clean"]  # the rest is imported
    assert counted == (rows["clean"] - rows["holed"]) * record  # exactly the records pymavlink lost
