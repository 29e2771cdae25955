"""Hostile files an outside tester feeds the commands that take a file, where the
capture reader's own checks (tests/test_cli_errors.py, tests/test_hostile_numeric.py,
tests/fuzzkit.py) do not reach: the plain-CSV importer, `station noise`, logs that warn and
then fail. Each one: one line on stderr naming the file (and line), exit status 2, nothing on
stdout, nothing written.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys

import pytest

from tests.station_run import ROOT, assert_one_line_refusal, run_station

SMALL = "\n".join(["time_s,gx,gy,gz"] + [f"{i * 0.01:.2f},0.01,0.02,-0.01" for i in range(400)]) + "\n"
IMPORT = ("--procedure", "gyro-drift", "--map", "t=time_s,gx=gx,gy=gy,gz=gz", "--unit", "gyro=rad/s,t=s")


def _limit_memory():  # the child's address space: far above what a 1 MB CSV needs, far below "all of it"
    resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))


def test_import_of_a_huge_file_of_nul_bytes_stops_at_once(tmp_path):
    """A CSV of NUL bytes larger than the memory the child may use: read whole before any
    check, /dev/zero filled the memory (6 GB in seconds); now the first block's NUL byte
    refuses it. (A device such as /dev/zero itself is refused before it is opened:
    tests/test_hostile_paths.py.) The file is sparse: 4 GiB on disk in name only."""
    src = tmp_path / "zeros.csv"
    with open(src, "wb") as f:
        f.truncate(4 << 30)
    out = tmp_path / "out.csv"
    res = subprocess.run(
        [sys.executable, "-m", "station", "import", str(src), *IMPORT, "--out", str(out)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
        preexec_fn=_limit_memory,
    )
    assert_one_line_refusal(res, f"{src}:1:", "NUL byte")
    assert not out.exists()


def test_import_of_a_file_without_line_ends_is_refused_by_line_length(tmp_path):
    src = tmp_path / "one_line.csv"
    src.write_bytes(b"time_s,gx,gy,gz," + b"7" * (3 << 20))
    out = tmp_path / "out.csv"
    assert_one_line_refusal(run_station("import", src, *IMPORT, "--out", out), f"{src}:1:", "line longer than")
    assert not out.exists()


def test_import_of_a_field_over_the_csv_modules_limit_names_the_line(tmp_path):
    """A 500 kB field: within the line limit, over the csv module's 128 kB field limit (its
    csv.Error reached the CLI's last-resort message)."""
    src = tmp_path / "long_field.csv"
    lines = SMALL.splitlines()
    lines[7] = lines[7] + "9" * 500_000
    src.write_text("\n".join(lines) + "\n")
    out = tmp_path / "out.csv"
    assert_one_line_refusal(
        run_station("import", src, *IMPORT, "--out", out), f"{src}:8:", "field larger than field limit"
    )
    assert not out.exists()


@pytest.mark.parametrize("where", ["first", "late"])
def test_import_nul_byte_is_named_by_its_line(tmp_path, where):
    lines = SMALL.splitlines()
    k = 1 if where == "first" else 350
    lines[k] = lines[k].replace("0.02", "0.0\0")
    src = tmp_path / "nul.csv"
    src.write_text("\n".join(lines) + "\n")
    assert_one_line_refusal(run_station("import", src, *IMPORT, "--out", tmp_path / "o.csv"), f"{src}:{k + 1}:", "NUL")


def test_import_of_a_good_file_still_reads_every_row(tmp_path):
    src = tmp_path / "good.csv"
    src.write_text(SMALL)
    out = tmp_path / "out.csv"
    res = run_station("import", src, *IMPORT, "--out", out)
    assert res.returncode == 0, res.stderr
    from station.capture import read_capture

    assert read_capture(out).n_rows == 400


# --- station noise ---------------------------------------------------------------------------

MPU_STATIC = ("mpu6050_unc", "mpu6050_unc_static_test.capture.csv")  # gyro and accel in counts


def _with_meta(src, dst, key_value: str, after: str = "# gyro_unit: counts\n"):
    text = src.read_text()
    assert after in text
    dst.write_text(text.replace(after, after + f"# {key_value}\n", 1))
    return dst


def test_noise_refuses_numbers_no_instrument_reports_naming_line_and_column(tmp_path, shared_data):
    src = shared_data / "sunsided_marg" / "sunsided_unmoved_x_forward.capture.csv"
    lines = src.read_text().splitlines(True)[:1200]
    k = next(i for i, line in enumerate(lines) if line.startswith("t,")) + 5
    cells = lines[k].split(",")
    cells[4] = "1e308"  # gx
    lines[k] = ",".join(cells)
    bad = tmp_path / "huge.csv"
    bad.write_text("".join(lines))
    assert_one_line_refusal(run_station("noise", bad, "--json"), f"{bad}:{k + 1}:", "column 'gx'", "beyond")


def test_noise_refuses_a_time_axis_that_does_not_advance(tmp_path, shared_data):
    src = shared_data / "sunsided_marg" / "sunsided_unmoved_x_forward.capture.csv"
    lines = src.read_text().splitlines(True)[:1200]
    h = next(i for i, line in enumerate(lines) if line.startswith("t,"))
    lines[h + 1 :] = ["0" + line[line.index(",") :] for line in lines[h + 1 :]]
    bad = tmp_path / "frozen.csv"
    bad.write_text("".join(lines))
    assert_one_line_refusal(run_station("noise", bad, "--json"), f"{bad}:", "does not advance")


def test_noise_refusal_names_the_file(shared_data):
    src = shared_data.joinpath(*MPU_STATIC)
    assert_one_line_refusal(run_station("noise", src, "--json"), f"{src}: ", "gyro_counts_per_deg_s")


def test_noise_of_gyro_counts_uses_the_nominal_scale_the_procedures_read(tmp_path, shared_data):
    """The MPU-6050 record in counts with its nominal 131 counts per °/s (the scale P4 reads)
    gives the figures of the same record converted to °/s by hand (two routes, one answer),
    and a noise density of the datasheet's order (InvenSense PS-MPU-6000A-00 rev 3.4: rate
    noise spectral density 0.005 °/s/√Hz typical; the board's filter setting moves it, so a
    factor 3 either way, where a missing scale would be 131 times off)."""
    import json

    import numpy as np

    from station.capture import Capture, read_capture, write_capture

    src = shared_data.joinpath(*MPU_STATIC)
    counts = _with_meta(src, tmp_path / "counts.csv", "gyro_counts_per_deg_s: 131")
    res = run_station("noise", counts, "--json")
    assert res.returncode == 0, res.stderr
    doc = json.loads(res.stdout)
    assert any("131" in n for n in doc["notes"])
    cap = read_capture(src)
    cols = {k: np.asarray(v) for k, v in cap.columns.items()}
    for c in ("gx", "gy", "gz"):
        cols[c] = cols[c] / 131.0
    meta = dict(cap.meta, gyro_unit="deg/s")
    by_hand = tmp_path / "degs.csv"
    write_capture(by_hand, Capture(meta, cols))
    ref = json.loads(run_station("noise", by_hand, "--json").stdout)
    np.testing.assert_allclose(doc["sensors"]["gyro"]["noise_density"], ref["sensors"]["gyro"]["noise_density"], 1e-6)
    datasheet_rad = np.radians(0.005)
    nd = np.asarray(doc["sensors"]["gyro"]["noise_density"])
    assert np.all((nd > datasheet_rad / 3) & (nd < datasheet_rad * 3)), nd


# --- a log that warns, then cannot be calibrated ------------------------------------------------


@pytest.mark.parametrize("command", ["calibrate", "diagnose", "inspect"])
def test_a_warning_before_a_refusal_is_part_of_the_one_error_line(shared_data, command):
    """A real CubeOrange log whose raw sensor topics were logged at 1 Hz: the importer warns
    (sensor_combined holds more), then P4 refuses the 5 samples. The refusal stays one line
    and carries the warning, which says what to do."""
    log = shared_data / "px4_ulog" / "original" / "sample_log_small.ulg"
    res = run_station(command, log, "--procedure", "gyro-drift", *(["--json"] if command != "inspect" else []))
    if command == "inspect":  # inspect succeeds: the warning comes after the summary
        assert res.returncode == 0, res.stderr
        # one line per warning: the raw topics' rate, and their several instances (3 accel, 3 gyro)
        lines = res.stderr.splitlines()
        assert len(lines) == 2 and all(line.startswith(f"station: {log}: warning: ") for line in lines), lines
        assert any("the raw sensor topics hold" in line for line in lines), lines
        assert any("the log has 3 sensor_accel" in line for line in lines), lines
        return
    assert_one_line_refusal(res, f"{log}: ", "warning: the raw sensor topics hold 6 samples", "--source combined")


def test_warnings_of_one_run_do_not_leak_into_the_next(shared_data, tmp_path):
    log = shared_data / "px4_ulog" / "original" / "sample_log_small.ulg"
    run_station("calibrate", log, "--procedure", "gyro-drift", "--json")
    res = run_station("calibrate", tmp_path / "missing.csv")
    assert_one_line_refusal(res, "no such file")
    assert "warning:" not in res.stderr


# --- --db that is not a database ----------------------------------------------------------------


@pytest.mark.parametrize("content", [b"", b"x", b"notes\n", b"device,interval\nIMU-1,365\n"])
@pytest.mark.parametrize("command", [["devices", "list"], ["due"], ["verify"], ["history", "IMU-1"]])
def test_a_reading_command_leaves_a_file_that_is_no_database_as_it_was(tmp_path, content, command):
    """SQLite takes a file shorter than its 100-byte header for an empty database and writes
    one over it: `station due --db notes.txt` replaced a one-line text file and said "nothing
    due"; an empty file became a database the same way."""
    path = tmp_path / "notes.txt"
    path.write_bytes(content)
    res = run_station(*command, "--db", path)
    assert_one_line_refusal(res, str(path))
    assert path.read_bytes() == content


def test_saving_into_a_short_text_file_leaves_it_as_it_was(tmp_path, shared_data):
    path = tmp_path / "notes.txt"
    path.write_bytes(b"x")
    cap = shared_data / "sunsided_marg" / "sunsided_full_sphere.capture.csv"
    res = run_station("calibrate", cap, "--save", "--override", "test", "--db", path)
    assert_one_line_refusal(res, str(path), "not a database")
    assert path.read_bytes() == b"x"


def test_noise_of_a_record_with_motion_says_so(shared_data):
    """The full-sphere compass turn (half of it moving) gave Allan figures with no word that
    they are not the sensor's noise; the real still records of the same board give none."""
    import json

    turn = json.loads(
        run_station("noise", shared_data / "sunsided_marg" / "sunsided_full_sphere.capture.csv", "--json").stdout
    )
    assert any("of the record moves" in w for w in turn.get("warnings", [])), turn.get("warnings")
    still = run_station("noise", shared_data / "sunsided_marg" / "sunsided_unmoved_x_forward.capture.csv", "--json")
    assert "warnings" not in json.loads(still.stdout)


def test_a_capture_cut_into_a_1_gib_hole_of_zeros_names_the_hole_at_once(tmp_path):
    """A capture whose file was sized but never written past a point (a crash, a copy onto a
    full card): a sparse 1 GiB of NUL bytes after 200 good rows. Refused at once on the line
    where the hole starts, saying what is there (it said only 'line longer than 1048576 bytes')."""
    path = tmp_path / "holed.csv"
    rows = "".join(f"{i * 0.01:.2f},0.01,0.02,-0.03\n" for i in range(200))
    path.write_text("# station-capture: 1\n# procedure: gyro-drift\n# gyro_unit: rad/s\nt,gx,gy,gz\n" + rows)
    os.truncate(path, 2**30)
    res = run_station("calibrate", path, subprocess_run=True)
    assert_one_line_refusal(res, f"{path}:205: ", "NUL bytes from column 1")
