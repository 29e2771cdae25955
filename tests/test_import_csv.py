"""`station import` of EuRoC / Kalibr IMU CSV files and of any CSV through --map and --unit.

EuRoC and Kalibr have no writer library: the files here use the header exactly as the EuRoC MAV
dataset publishes it (``mav0/imu0/data.csv``: ``#timestamp [ns],w_RS_S_x [rad s^-1],…``) and as
Kalibr's ``kalibr_bagcreater`` documents its ``imu0.csv`` (``timestamp,omega_x,…,alpha_z``; ns,
rad/s, m/s²).
"""

from __future__ import annotations

import numpy as np
import pytest

from station.capture import read_capture
from tests.station_run import assert_one_line_refusal, run_station

EUROC = (
    "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
    "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]"
)
KALIBR = "timestamp,omega_x,omega_y,omega_z,alpha_x,alpha_y,alpha_z"
T0 = 1403636579758555392  # EuRoC MH_01's first IMU stamp (ns)


def _imu_rows(rng, n=600, hz=200):
    t = T0 + np.round(np.arange(n) * 1e9 / hz).astype(np.int64) + rng.integers(-300, 300, n)
    w = rng.normal(0, 0.002, (n, 3))
    a = np.array([8.15, -0.38, -2.40]) + rng.normal(0, 0.02, (n, 3))
    return t, w, a


def _write_imu_csv(path, header, t_ns, w, a):
    """An EuRoC/Kalibr ``data.csv``: the header line, then one row a sample (ns stamp, ω, a)."""
    rows = (
        ",".join([str(ti)] + [repr(x) for x in wi + ai]) for ti, wi, ai in zip(t_ns.tolist(), w.tolist(), a.tolist())
    )
    path.write_text(header + "\n" + "".join(row + "\n" for row in rows))
    return path


@pytest.mark.parametrize("header", [EUROC, KALIBR])
def test_euroc_and_kalibr_round_trip(tmp_path, header):
    t, w, a = _imu_rows(np.random.default_rng(1))
    src = _write_imu_csv(tmp_path / "data.csv", header, t, w, a)
    out = tmp_path / "c.csv"
    res = run_station("import", src, "--procedure", "gyro-drift", "--out", out)
    assert res.returncode == 0, res.stderr
    c = read_capture(out)
    assert (c.meta["accel_unit"], c.meta["gyro_unit"]) == ("m/s^2", "rad/s")
    np.testing.assert_array_equal(c.columns["gx"], w[:, 0])
    np.testing.assert_array_equal(c.columns["az"], a[:, 2])
    # ns stamps kept to the nanosecond (a float64 of 1.4e18 ns would round them to 256 ns)
    np.testing.assert_allclose(c.columns["t"], (t - t[0]) * 1e-9, rtol=0, atol=1e-12)
    # calibrate reads it directly; a file with accel and gyro needs the procedure named
    res = run_station("calibrate", src)
    assert res.returncode == 2 and "--procedure" in res.stderr and res.stderr.count("\n") == 1
    res = run_station("calibrate", src, "--procedure", "gyro-drift")
    assert "Traceback" not in res.stderr and (res.returncode == 0 or res.stderr.count("\n") == 1)


def test_euroc_bad_cell_names_file_and_line(tmp_path):
    src = tmp_path / "data.csv"
    src.write_text(EUROC + "\n" + f"{T0},0,0,0,0,0,9.8\n{T0 + 5_000_000},0,0,abc,0,0,9.8\n")
    res = run_station("import", src, "--procedure", "gyro-drift", "--out", tmp_path / "o.csv")
    assert res.returncode == 2 and res.stderr.strip() == f"station: {src}:3: column 'gz': 'abc' is not a number"
    assert not (tmp_path / "o.csv").exists()


def test_plain_csv_is_refused_by_calibrate_with_the_way_in(tmp_path):
    src = tmp_path / "bench.csv"
    src.write_text("t,ax,ay,az\n0,0.01,0.02,1.0\n0.01,0.01,0.02,1.0\n")
    res = run_station("calibrate", src)
    assert res.returncode == 2 and res.stderr.count("\n") == 1
    assert f"{src}:1:" in res.stderr and "station import" in res.stderr
    # station import takes it once the unit is known (the names already are the capture's)
    res = run_station("import", src, "--procedure", "accel-tabletop", "--out", tmp_path / "o.csv")
    assert res.returncode == 2 and "--unit accel=UNIT" in res.stderr
    res = run_station(
        "import",
        src,
        "--procedure",
        "accel-tabletop",
        "--unit",
        "accel=g",
        "--out",
        tmp_path / "o.csv",
    )
    assert res.returncode == 0, res.stderr
    c = read_capture(tmp_path / "o.csv")
    assert c.meta["accel_unit"] == "g" and c.columns["az"].tolist() == [1.0, 1.0]


def test_plain_csv_with_map_units_and_time_in_ms(tmp_path):
    rng = np.random.default_rng(2)
    n = 50
    t_ms = np.arange(n) * 10.0
    acc = rng.normal(0, 0.01, (n, 3)) + [0, 0, 1]
    gyr = rng.normal(0, 0.1, (n, 3))
    mag = rng.normal(0, 0.5, (n, 3)) + [20, 0, -40]
    src = tmp_path / "logger.csv"
    lines = [
        "# exported by the bench logger",
        "time_ms;temp;acc_x;acc_y;acc_z;gyr_x;gyr_y;gyr_z;mag_x;mag_y;mag_z",
    ]
    lines += [""] * n
    lines[2:] = [";".join(repr(float(x)) for x in [t_ms[i], 25.5, *acc[i], *gyr[i], *mag[i]]) for i in range(n)]
    src.write_text("\n".join(lines) + "\n")
    out = tmp_path / "o.csv"
    res = run_station(
        "import",
        src,
        "--procedure",
        "compass",
        "--out",
        out,
        "--map",
        "t=time_ms,ax=acc_x,ay=acc_y,az=acc_z,temp_c=2",
        "--map",
        "gx=gyr_x,gy=gyr_y,gz=gyr_z,mx=mag_x,my=mag_y,mz=mag_z",
        "--unit",
        "accel=g,gyro=deg/s,mag=uT,t=ms",
        "--device",
        "BENCH-7",
    )
    assert res.returncode == 0, res.stderr
    c = read_capture(out)
    assert (c.meta["accel_unit"], c.meta["gyro_unit"], c.meta["mag_unit"]) == (
        "g",
        "deg/s",
        "uT",
    )
    assert c.meta["device"] == "BENCH-7"
    np.testing.assert_allclose(c.columns["t"], t_ms / 1000, atol=1e-12)
    np.testing.assert_array_equal(c.columns["mx"], mag[:, 0])
    np.testing.assert_array_equal(c.columns["gz"], gyr[:, 2])


def test_the_rows_are_joined_without_holding_them_twice(monkeypatch):
    """Joining the parsed chunks held every chunk and every joined column at once: the
    traced peak of the row reader was twice its result. Now each chunk is freed as it is
    copied: the peak is the result and one column, plus the rows not yet made numbers
    (made few here so that they do not hide the join). The lines are read before tracing:
    the file's reading is not what is measured. Memory, not time."""
    import tracemalloc

    from station.importers import csvfiles

    monkeypatch.setattr(csvfiles, "_FLUSH_ROWS", 2048)
    n = 120_000
    lines = [(i + 2, f"{i},0.{i % 97},-0.5,1.25,24.5") for i in range(n)]
    cols = {"t": 0, "ax": 1, "ay": 2, "az": 3, "temp_c": 4}
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        values, linenos = csvfiles._rows("bench.csv", iter(lines), 2, ",", 5, cols)
        peak = tracemalloc.get_traced_memory()[1] - before
    finally:
        tracemalloc.stop()
    result = linenos.nbytes + sum(v.nbytes for v in values.values())
    assert result == n * 8 * 6
    np.testing.assert_array_equal(values["t"], np.arange(n))
    np.testing.assert_array_equal(linenos, np.arange(n) + 2)
    assert peak < 1.35 * result, (peak, result)  # was 2.0x: chunks and joined columns together


def test_a_plain_csv_of_many_megabytes_reads_whole_and_names_a_bad_line_far_in(tmp_path):
    """The reader streams the file a megabyte at a time: rows across the seams (CRLF ends, a
    UTF-8 byte-order mark, non-ASCII comments, a line end split between reads) come back
    exactly, and a bad cell deep in the file is named by its line."""
    rng = np.random.default_rng(5)
    n = 100_000  # ~3.5 MiB: several reads
    t_ms = np.arange(n) * 10
    acc = np.round(rng.normal(0, 0.01, (n, 3)) + [0, 0, 1], 6)
    rows = [f"{t},{x!r},{y!r},{z!r}" for t, (x, y, z) in zip(t_ms.tolist(), acc.tolist())]
    for i in range(0, n, 997):  # comments and blank lines among the rows, not rows
        rows[i] += "\r\n# bench note: 20 °C, Ω≈μ\r\n"
    text = "\ufefftime_ms,acc_x,acc_y,acc_z\r\n" + "\r\n".join(rows) + "\r\n"
    assert len(text.encode()) > 3 * (1 << 20)
    src = tmp_path / "big.csv"
    src.write_bytes(text.encode())
    opts = ["--procedure", "accel-tabletop", "--map", "t=time_ms,ax=acc_x,ay=acc_y,az=acc_z", "--unit", "accel=g,t=ms"]
    out = tmp_path / "o.csv"
    res = run_station("import", src, "--out", out, *opts)
    assert res.returncode == 0, res.stderr
    c = read_capture(out)
    np.testing.assert_allclose(c.columns["t"], t_ms / 1000, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(np.column_stack([c.columns[k] for k in ("ax", "ay", "az")]), acc)

    k = 55_555  # the row's line: the header, its rows before it, two lines per note before it
    lineno = 1 + k + 1 + 2 * len(range(0, k, 997))
    bad = text.replace("\r\n" + rows[k] + "\r\n", "\r\n" + rows[k].replace(",", ",x", 1) + "\r\n")
    src.write_bytes(bad.encode())
    res = run_station("import", src, "--out", tmp_path / "bad.csv", *opts)
    assert_one_line_refusal(res, f"big.csv:{lineno}: column 'ax'", "is not a number")
    assert not (tmp_path / "bad.csv").exists()


def test_plain_csv_without_time_uses_rate(tmp_path):
    src = tmp_path / "adc.csv"
    src.write_text("x,y,z\n" + "".join(f"{2.5 + 0.001 * i},{1.6},{1.7}\n" for i in range(10)))
    out = tmp_path / "o.csv"
    opts = ["--procedure", "accel-tabletop", "--map", "ax=x,ay=y,az=z", "--unit", "accel=V", "--out", out]
    res = run_station("import", src, *opts)
    assert res.returncode == 2 and "--rate HZ" in res.stderr
    res = run_station("import", src, *opts, "--rate", "100")
    assert res.returncode == 0, res.stderr
    np.testing.assert_allclose(read_capture(out).columns["t"], np.arange(10) / 100)


@pytest.mark.parametrize(
    "content, args, says",
    [
        (
            "t,ax,ay,az\n0,1,2,3\n1,1,x,3\n",
            ("--unit", "accel=g"),
            ":3: column 'ay': 'x' is not a number",
        ),
        (
            "t,ax,ay,az\n0,1,2,3\n1,1,2\n",
            ("--unit", "accel=g"),
            ":3: 3 fields where the header has 4",
        ),
        (
            "t,ax,ay,az\n0,1,2,3\n-1,1,2,3\n",
            ("--unit", "accel=g"),
            ":3: time goes backwards",
        ),
        (  # was: 'fewer than 2 accelerometer samples where all sensors overlap', no line
            "t,ax,ay,az\n" + "5,1,2,3\n" * 50,
            ("--unit", "accel=g"),
            ":2: the time axis does not advance (50 rows, all at t = 5)",
        ),
        (
            "t,ax,ay,az\n0,1,2,3\n",
            ("--unit", "accel=furlongs"),
            "--unit accel=furlongs: not an accel unit",
        ),
        ("t,ax,ay\n0,1,2\n", ("--unit", "accel=g"), "map all three of ax, ay, az"),
        (
            "t,ax,ay,az\n0,1,2,3\n",
            ("--unit", "accel=g", "--map", "ax=nope"),
            "no column 'nope' in the header",
        ),
        ("1,2,3\n4,5,6\n", ("--unit", "accel=g"), ":1: no header row"),
    ],
)
def test_plain_csv_bad_input_one_line(tmp_path, content, args, says):
    src = tmp_path / "in.csv"
    src.write_text(content)
    out = tmp_path / "o.csv"
    res = run_station("import", src, "--procedure", "accel-tabletop", "--out", out, *args)
    assert res.returncode == 2 and res.stdout == "" and "Traceback" not in res.stderr
    assert res.stderr.count("\n") == 1 and says in res.stderr, res.stderr
    assert not out.exists()


def test_options_that_do_not_apply_are_refused(tmp_path, shared_data):
    log = shared_data / "px4_ulog" / "original" / "sample_px4_events.ulg"
    res = run_station(
        "import",
        log,
        "--procedure",
        "accel-tabletop",
        "--unit",
        "accel=g",
        "--out",
        tmp_path / "o.csv",
    )
    assert res.returncode == 2 and "apply to plain CSV files" in res.stderr


def test_a_station_capture_needs_no_import(tmp_path):
    src = tmp_path / "c.csv"
    src.write_text("# station-capture: 1\n# procedure: accel-tabletop\n# accel_unit: g\nt,ax,ay,az\n0,0,0,1\n")
    res = run_station("import", src, "--procedure", "accel-tabletop", "--out", tmp_path / "o.csv")
    assert res.returncode == 2 and f"{src}:1: already a station capture" in res.stderr


def test_a_loggers_preamble_above_the_header_is_skipped_and_said(tmp_path, shared_data):
    """The MPU-6050 logger's files (shared data, mpu6050_unc) open with 'Fs,100', 'Logging
    Type,1', ... and name the columns on line 5: the first line was taken for the header, so
    neither `--map ax=ax,...` nor the capture's own names could import them. The
    header is now the first line naming the columns asked for, the lines above it are said in a
    warning, and a bad cell further on still names its own line."""
    src = shared_data / "mpu6050_unc" / "original" / "imu_static_test.csv"
    lines = src.read_text().splitlines()
    assert lines[4] == "ax,ay,az,gx,gy,gz"  # the file as its logger wrote it
    rows = np.array([[float(c) for c in line.split(",")] for line in lines[5:] if line.strip()])
    units = ("--unit", "accel=counts,gyro=counts", "--rate", "100")
    for opts in ((), ("--map", "ax=ax,ay=ay,az=az,gx=gx,gy=gy,gz=gz")):
        out = tmp_path / "o.csv"
        res = run_station("import", src, "--procedure", "gyro-drift", *opts, *units, "--out", out)
        assert res.returncode == 0, res.stderr
        assert "lines 1-4 above the header (line 5)" in res.stderr and "'Fs,100'" in res.stderr
        cap = read_capture(out)
        got = np.column_stack([cap.columns[c] for c in ("ax", "ay", "az", "gx", "gy", "gz")])
        np.testing.assert_array_equal(got, rows)  # every data row, none of the preamble
        out.unlink()
    bad = tmp_path / "bad.csv"
    bad.write_text("\n".join(lines[:9] + ["748,244,oops,-480,193,-83"] + lines[10:]) + "\n")
    res = run_station("import", bad, "--procedure", "gyro-drift", *units, "--out", tmp_path / "b.csv")
    assert_one_line_refusal(res, f"{bad}:10:", "'oops'")
    assert not (tmp_path / "b.csv").exists()
    # a name no line has is still refused against the first line
    res = run_station(
        "import", src, "--procedure", "gyro-drift", "--map", "ax=acc_x", *units, "--out", tmp_path / "c.csv"
    )
    assert_one_line_refusal(res, f"{src}:1:", "no column 'acc_x'")


def test_what_a_loggers_csv_leaves_unsaid_is_said_at_once_on_its_header_line(tmp_path, shared_data):
    """The MPU-6050 logger's file (shared data) names its columns but no unit and has no time
    column: `station: give the accel unit: ...` named neither the file nor its line, and after
    --unit accel=... came the gyro's unit, then the time, one run each."""
    src = shared_data / "mpu6050_unc" / "original" / "imu_static_test.csv"
    out = tmp_path / "o.csv"
    units = (
        "the file does not say the unit of its accelerometer and gyro columns: "
        "give --unit accel=UNIT,gyro=UNIT (accel: V, mV, counts, g, m/s^2, mps2, mg; "
        "gyro: V, mV, counts, rad/s, deg/s, mrad/s, deg/h)"
    )
    res = run_station("import", src, "--procedure", "gyro-drift", "--out", out)
    # its 'Fs,100' line says the rate (test_the_rate_a_loggers_preamble_declares_numbers_the_rows)
    assert_one_line_refusal(res, f"station: {src}:5: {units}\n")
    # a file without such a line needs the rate too, said in the same line
    headless = tmp_path / "no_fs.csv"
    headless.write_text("\n".join(src.read_text().splitlines()[4:]) + "\n")
    res = run_station("import", headless, "--procedure", "gyro-drift", "--out", out)
    assert_one_line_refusal(
        res,
        f"station: {headless}:1: {units}; it has no time column either: --map t=COLUMN or the sample rate, --rate HZ",
    )
    res = run_station(
        "import", headless, "--procedure", "gyro-drift", "--unit", "accel=counts,gyro=counts", "--out", out
    )
    assert_one_line_refusal(res, f"station: {headless}:1: no time column: map one (--map t=COLUMN)")
    assert not out.exists()


def test_a_csv_whose_columns_have_other_names_lists_them(tmp_path, shared_data):
    """imucal's example session (shared data) names its columns n_samples, gyr_x, ... acc_z:
    the refusal said only what the station's names are, not the file's to map them from."""
    src = shared_data / "imucal_ferraris" / "original" / "example_ferraris_session.csv"
    res = run_station("import", src, "--procedure", "accel-tabletop", "--out", tmp_path / "o.csv")
    assert_one_line_refusal(
        res,
        f"{src}:1: no column is named like a capture column (t, ax, ay, az, gx, gy, gz, mx, my, mz, temp_c); "
        "its columns: 'n_samples', 'gyr_x', 'gyr_y', 'gyr_z', 'acc_x', 'acc_y', 'acc_z': say which is which",
    )


@pytest.mark.parametrize(("bits", "unit", "step"), [(32, "us", 10_000), (16, "ms", 10), (32, "ms", 10)])
def test_a_wrapping_counter_as_time_is_unwrapped_with_a_warning(tmp_path, bits, unit, step):
    """A logger's time stamp from a 32-bit micros() (wraps after 71.6 min) or a 16-bit
    millisecond counter (65.5 s) was refused at the wrap ('time goes backwards'): the log could
    not be imported at all. Each wrap adds 2**bits; a warning says so; the rows are all kept."""
    wrap = 2**bits
    counts = (wrap - 5 * step + step * np.arange(400)) % wrap
    src = tmp_path / "logger.csv"
    src.write_text("t,gx,gy,gz\n" + "".join(f"{c},0.01,0.02,-0.01\n" for c in counts))
    out = tmp_path / "out.csv"
    res = run_station("import", src, "--procedure", "gyro-drift", "--unit", f"gyro=rad/s,t={unit}", "--out", out)
    assert res.returncode == 0, res.stderr
    assert f"wraps at 2^{bits}" in res.stderr and "line 7" in res.stderr, res.stderr
    t = read_capture(out).columns["t"]
    scale = {"us": 1e-6, "ms": 1e-3}[unit]
    np.testing.assert_allclose(t, step * scale * np.arange(400), atol=1e-9)


def test_a_time_column_that_goes_back_by_less_than_a_wrap_is_still_refused(tmp_path):
    """Unwrapping takes only a fall from near the counter's top to near its start: a row out of
    order is refused as before."""
    counts = [1000, 2000, 3000, 1500, 4000]  # an unwrap by 2^16 would make it a 62 s jump forward
    src = tmp_path / "logger.csv"
    src.write_text("t,gx,gy,gz\n" + "".join(f"{c},0.01,0.02,-0.01\n" for c in counts))
    res = run_station(
        "import", src, "--procedure", "gyro-drift", "--unit", "gyro=rad/s,t=us", "--out", tmp_path / "o.csv"
    )
    assert_one_line_refusal(res, ":5: time goes backwards")


@pytest.mark.parametrize(
    ("mapping", "extra", "says"),
    [
        ("t=t,gx=a,gy=a,gz=c", (), "--map: column 'a' (2) is given for both gx and gy"),
        ("t=1,gx=2,gy=3,gz=4,temp_c=a", (), "--map: column 'a' (2) is given for both gx and temp_c"),
        ("t=t,gx=a,gy=b,gz=c", ("--rate", "100"), "--rate is for a file without a time column"),
    ],
    ids=["one-column-two-axes", "by-name-and-number", "rate-beside-t"],
)
def test_a_mapping_that_cannot_mean_what_it_says_is_refused(tmp_path, mapping, extra, says):
    """--map gx=a,gy=a gave two gyro axes one column's samples, --map gx=2,temp_c=a made the
    gyro's x rate the temperature, and --rate beside a mapped t column was ignored: each
    imported with exit 0. Refused in one line, nothing written."""
    src = tmp_path / "bench.csv"
    src.write_text("t,a,b,c\n" + "".join(f"{i * 0.01:.2f},0.1,0.2,0.3\n" for i in range(300)))
    out = tmp_path / "out.csv"
    res = run_station(
        "import", src, "--procedure", "gyro-drift", "--map", mapping, "--unit", "gyro=rad/s,t=s", *extra, "--out", out
    )
    assert_one_line_refusal(res, says)
    assert not out.exists()


@pytest.mark.parametrize("device", ["IMU\n42", "\x1b[31mIMU", " IMU"])
def test_a_device_id_no_capture_can_hold_is_refused_naming_the_option(tmp_path, device):
    """import --device 'IMU<newline>42' read the whole file, then blamed the output
    ('out.csv: metadata 'device' ... cannot be written'). Refused first, naming --device."""
    src = tmp_path / "bench.csv"
    src.write_text("t,a,b,c\n" + "".join(f"{i * 0.01:.2f},0.1,0.2,0.3\n" for i in range(300)))
    out = tmp_path / "out.csv"
    res = run_station(
        "import", src, "--procedure", "gyro-drift", "--map", "t=t,gx=a,gy=b,gz=c", "--unit", "gyro=rad/s,t=s",
        "--device", device, "--out", out,
    )  # fmt: skip
    assert_one_line_refusal(res, "--device ", "control character or spaces at its ends")
    assert str(out) not in res.stderr and not out.exists()


def test_calibrate_of_a_log_with_a_device_id_no_capture_can_hold_names_the_option(shared_data):
    """calibrate flight.ulg --device 'a<newline>b' named the importer's temporary capture
    ('station-import-.../capture.csv: metadata 'device' ...', in the system's temporary folder),
    a path the operator never gave."""
    log = shared_data / "px4_ulog" / "original" / "sample_log_small.ulg"
    res = run_station("calibrate", log, "--procedure", "gyro-drift", "--device", "a\nb")
    assert_one_line_refusal(res, "--device 'a\\nb'", "control character")
    assert "station-import" not in res.stderr


@pytest.mark.parametrize(
    "rate, needle",
    [
        ("1e300", "--rate must be a positive number of Hz, at most 1e+09, got 1e+300"),
        ("1e-300", "--rate 1e-300: 3 rows"),
    ],
)
@pytest.mark.parametrize("command", ["import", "calibrate"])
def test_a_rate_no_capture_can_hold_is_refused_as_the_option(tmp_path, rate, needle, command):
    """`--rate 1e300` was refused as "o.csv: metadata 'sample_rate_hz': '1e+300' must be ... at
    most 1e9", naming the output (or 'the capture made from it') and a metadata key the operator
    never wrote; `--rate 1e-300` as "o.csv: column 't', row 2: inf cannot be written", and
    `--rate 1e-30` wrote a capture whose t (2e30 s) the station's own reader refuses. Now the
    option is named, nothing written."""
    src = tmp_path / "plain.csv"
    src.write_text("ax,ay,az\n0,0,9.8\n0,0,9.81\n0,0,9.79\n")
    out = tmp_path / "o.csv"
    args = ["--out", out] if command == "import" else ["--format", "csv"]
    res = run_station(command, src, "--procedure", "accel-tabletop", "--unit", "accel=m/s^2", "--rate", rate, *args)
    assert_one_line_refusal(res, needle)
    assert "o.csv" not in res.stderr and "metadata" not in res.stderr and not out.exists()


@pytest.mark.parametrize("column, t_values", [("time_ms", np.arange(200) * 10.0), ("stamp", np.arange(200) * 10.0)])
def test_a_time_column_in_ms_read_as_seconds_is_warned_about(tmp_path, column, t_values):
    """A bench logger's time in ms at 100 Hz, imported without ``--unit t=ms``: read as seconds it
    is a 0.1 Hz record of 33 minutes, which P4 then calibrated without a word. The import still
    writes what it was told, and says on stderr which unit the column looks like."""
    rng = np.random.default_rng(4)
    src = tmp_path / "logger.csv"
    rows = [f"{column},gx,gy,gz,ax,ay,az"]
    rows += [",".join(repr(float(x)) for x in [t, *rng.normal(0, 1e-3, 3), 0.0, 0.0, 9.81]) for t in t_values]
    src.write_text("\n".join(rows) + "\n")
    out = tmp_path / "o.csv"
    res = run_station(
        "import",
        src,
        "--procedure",
        "gyro-drift",
        "--out",
        out,
        "--map",
        f"t={column},gx=gx,gy=gy,gz=gz,ax=ax,ay=ay,az=az",
        "--unit",
        "gyro=rad/s,accel=m/s^2",
    )
    assert res.returncode == 0, res.stderr
    assert "--unit t=ms" in res.stderr and repr(column) in res.stderr, res.stderr
    assert read_capture(out).columns["t"][-1] == pytest.approx(1990.0)  # what it was told: seconds


def test_a_time_column_in_seconds_or_with_its_unit_given_is_not_warned_about(tmp_path):
    rng = np.random.default_rng(5)
    src = tmp_path / "logger.csv"
    rows = ["time_ms,t_s,gx,gy,gz,ax,ay,az"]
    rows += [
        ",".join(repr(float(x)) for x in [10.0 * i, 0.01 * i, *rng.normal(0, 1e-3, 3), 0.0, 0.0, 9.81])
        for i in range(200)
    ]
    src.write_text("\n".join(rows) + "\n")
    common = ("--procedure", "gyro-drift", "--unit")
    for t_map, units in (("t=t_s", "gyro=rad/s,accel=m/s^2"), ("t=time_ms", "gyro=rad/s,accel=m/s^2,t=ms")):
        res = run_station(
            "import",
            src,
            *common,
            units,
            "--out",
            tmp_path / "o.csv",
            "--map",
            f"{t_map},gx=gx,gy=gy,gz=gz,ax=ax,ay=ay,az=az",
        )
        assert res.returncode == 0, res.stderr
        assert "--unit t=" not in res.stderr, res.stderr


def test_a_csv_without_a_header_row_is_read_with_its_columns_named_by_number(tmp_path, shared_data):
    """imu_tk's Xsens recording (shared data; text despite its '.mat' name) has no header row:
    four numbers a line, t and the accelerometer in counts. It was refused "no header row: the
    first line must name the columns", though --map names columns by number ("e.g. --map
    ax=2"); the numbered map reads it, every line data, and the refusal says so."""
    src = shared_data / "imu_tk_xsens" / "original" / "xsens_acc.mat"
    rows = np.loadtxt(src)
    assert rows.shape == (51175, 4)  # the file as imu_tk's authors wrote it (%15.7e)
    out = tmp_path / "o.csv"
    res = run_station("import", src, "--procedure", "accel-tabletop", "--format", "csv", "--out", out)
    assert_one_line_refusal(
        res,
        f"{src}:1: no header row: this line holds 4 numbers; name the columns by their number "
        "(--map t=1,ax=2,... of 1-4) or add a first line that names them",
    )
    mapped = ("--map", "t=1,ax=2,ay=3,az=4", "--unit", "accel=counts")
    res = run_station("import", src, "--procedure", "accel-tabletop", "--format", "csv", *mapped, "--out", out)
    assert res.returncode == 0, res.stderr
    cap = read_capture(out)
    np.testing.assert_array_equal(np.column_stack([cap.columns[c] for c in ("ax", "ay", "az")]), rows[:, 1:])
    np.testing.assert_allclose(cap.columns["t"], rows[:, 0] - rows[0, 0], atol=1e-9)
    # a bad cell still names its own line (line 1 is data: line 2 is the second row)
    bad = tmp_path / "bad.txt"
    bad.write_text("0.01 1 2 3\n0.02 1 2 x\n0.03 1 2 3\n")
    res = run_station("import", bad, "--procedure", "accel-tabletop", "--format", "csv", *mapped, "--out", out)
    assert_one_line_refusal(res, f"{bad}:2: column 'az': 'x' is not a number")


# ------------------------------------------------------------------ QA s26: first line, Fs, epoch


def _write_rows(path, rows, header=None) -> None:
    """A CSV as Python's csv module writes it (the format's own writer)."""
    import csv

    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        if header is not None:
            w.writerow(header)
        w.writerows(rows)


def test_a_first_line_of_numbers_with_a_bad_field_is_a_data_row_not_a_header(tmp_path, shared_data):
    """A plain CSV without a header whose first data row has one corrupt field (`1.0,2.0,abc`)
    was taken as its header (QA s26): with --map by numbers it lost that row without a word
    (`0.00,0.1,0.2,abc` → 2 rows imported of 3), without --map it was refused for having no
    capture-named column, '0.0', '1', ... A first line is a header only when (almost) all its
    fields are names; else it is a data row and its bad field is refused on its line, exit 2."""
    src = shared_data / "mpu6050_unc" / "original" / "imu_static_test.csv"
    rows = [line.split(",") for line in src.read_text().splitlines()[5:25]]  # real samples, counts
    bad = tmp_path / "bad.csv"
    _write_rows(bad, [rows[0][:2] + ["abc"] + rows[0][3:]] + rows[1:])
    out = tmp_path / "o.csv"
    opts = ("--procedure", "gyro-drift", "--unit", "accel=counts,gyro=counts", "--rate", "100", "--out", out)
    res = run_station("import", bad, "--map", "ax=1,ay=2,az=3,gx=4,gy=5,gz=6", *opts)
    assert_one_line_refusal(res, f"station: {bad}:1: column 'az': 'abc' is not a number")
    res = run_station("import", bad, *opts)
    assert_one_line_refusal(res, f"station: {bad}:1: field 3: 'abc' is not a number, in a data row")
    assert not out.exists()
    short = tmp_path / "short.csv"
    _write_rows(short, [["1.0", "2.0", "abc"], ["1.0", "2.0", "9.8"]])
    res = run_station(
        "import", short, "--procedure", "accel-tabletop", "--map", "ax=1,ay=2,az=3", "--unit", "accel=g",
        "--rate", "100", "--out", out,
    )  # fmt: skip
    assert_one_line_refusal(res, f"station: {short}:1: column 'az': 'abc' is not a number")
    res = run_station(
        "import", short, "--procedure", "accel-tabletop", "--map", "ax=acc_x,ay=2,az=3", "--unit", "accel=g",
        "--rate", "100", "--out", out,
    )  # fmt: skip
    assert_one_line_refusal(
        res, f"station: {short}:1: --map ax=acc_x: no column 'acc_x'", "no header (2 of its 3 fields are numbers)"
    )
    # the same rows, whole, are read from line 1 on; a header of names is still a header
    good = tmp_path / "good.csv"
    _write_rows(good, rows)
    res = run_station("import", good, "--map", "ax=1,ay=2,az=3,gx=4,gy=5,gz=6", *opts)
    assert res.returncode == 0, res.stderr
    assert read_capture(out).n_rows == len(rows)
    named = tmp_path / "named.csv"
    _write_rows(named, rows, header=["ax", "ay", "az", "gx", "gy", "gz"])
    res = run_station("import", named, *opts[:-1], tmp_path / "n.csv")
    assert res.returncode == 0 and res.stderr == "", res.stderr
    assert read_capture(tmp_path / "n.csv").n_rows == len(rows)


def test_the_rate_a_loggers_preamble_declares_numbers_the_rows(tmp_path, shared_data):
    """The MPU-6050 logger's `Fs,100` line (shared data, mpu6050_unc) was skipped with the rest
    of its preamble and `--rate` still required (QA s26). The rate it declares now numbers the
    rows, said in one warning line; a --rate that differs wins, said; a time column that
    disagrees with it is said too (and kept)."""
    src = shared_data / "mpu6050_unc" / "original" / "imu_static_test.csv"
    lines = src.read_text().splitlines()
    assert lines[0] == "Fs,100"
    opts = ("--procedure", "gyro-drift", "--unit", "accel=counts,gyro=counts")
    res = run_station("import", src, *opts, "--out", tmp_path / "fs.csv")
    assert res.returncode == 0, res.stderr
    assert "no time column: the rows are numbered at the 100 Hz line 1 declares ('Fs,100')" in res.stderr
    res = run_station("import", src, *opts, "--rate", "100", "--out", tmp_path / "rate.csv")
    assert res.returncode == 0 and "declares" not in res.stderr, res.stderr
    by_fs, by_rate = read_capture(tmp_path / "fs.csv"), read_capture(tmp_path / "rate.csv")
    assert by_fs.meta["sample_rate_hz"] == "100" and by_fs.n_rows == len(lines) - 5
    np.testing.assert_array_equal(by_fs.columns["t"], by_rate.columns["t"])
    # columns by number: the header under the preamble is found too (it was 'no column 3 in the
    # header (Fs, 100)')
    res = run_station("import", src, *opts, "--map", "ax=1,ay=2,az=3,gx=4,gy=5,gz=6", "--out", tmp_path / "n.csv")
    assert res.returncode == 0 and "'Fs,100'" in res.stderr, res.stderr
    by_number = read_capture(tmp_path / "n.csv")
    for c in ("t", "ax", "gz"):
        np.testing.assert_array_equal(by_number.columns[c], by_fs.columns[c])
    res = run_station("import", src, *opts, "--rate", "50", "--out", tmp_path / "r50.csv")
    assert res.returncode == 0, res.stderr
    assert "--rate 50 differs from the 100 Hz line 1 declares ('Fs,100'): --rate used" in res.stderr
    assert read_capture(tmp_path / "r50.csv").meta["sample_rate_hz"] == "50"
    # the same preamble over rows with their own time, 200 Hz: the file contradicts itself
    timed = tmp_path / "timed.csv"
    rows = [[f"{i / 200:.3f}", *line.split(",")] for i, line in enumerate(lines[5:505])]
    timed.write_text("\n".join(lines[:4]) + "\n")
    with open(timed, "a", newline="") as f:
        import csv

        w = csv.writer(f)
        w.writerow(["t", "ax", "ay", "az", "gx", "gy", "gz"])
        w.writerows(rows)
    res = run_station("import", timed, *opts, "--out", tmp_path / "t.csv")
    assert res.returncode == 0, res.stderr
    assert "median step, 0.005 s (200 Hz), disagrees with the 100 Hz line 1 declares ('Fs,100')" in res.stderr
    assert read_capture(tmp_path / "t.csv").meta["sample_rate_hz"] == "200"


@pytest.mark.parametrize(
    ("column", "unit", "first"),
    [("time_s", "s", 1732900000.0), ("time_ms", "ms", 1732900000000), ("stamp_ns", "ns", 1732900000000000000)],
)
def test_a_unix_time_column_gives_the_capture_its_date(tmp_path, column, unit, first):
    """A time column in seconds, ms or ns since 1970 gave no `date` (QA s26): the calibration was
    then dated by its save. Now its first sample, in UTC, is the capture's date; `t` still
    starts at 0. 1732900000 s is 2024-11-29 17:06:40 UTC."""
    step = {"s": 0.01, "ms": 10, "ns": 10_000_000}[unit]
    src = tmp_path / "epoch.csv"
    _write_rows(src, [[first + i * step, 0.01, -0.02, 1.0] for i in range(200)], header=[column, "x", "y", "z"])
    out = tmp_path / "o.csv"
    res = run_station(
        "import", src, "--procedure", "accel-tabletop", "--map", f"t={column},ax=x,ay=y,az=z",
        "--unit", f"accel=g,t={unit}", "--out", out,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    cap = read_capture(out)
    assert cap.meta["date"] == "2024-11-29T17:06:40"
    assert cap.columns["t"][0] == 0 and abs(cap.columns["t"][-1] - 1.99) < 1e-6
    # a logger's time since power-up is no date
    _write_rows(src, [[5.0 + i * 0.01, 0.01, -0.02, 1.0] for i in range(200)], header=["t", "ax", "ay", "az"])
    res = run_station("import", src, "--procedure", "accel-tabletop", "--unit", "accel=g", "--out", out)
    assert res.returncode == 0, res.stderr
    assert "date" not in read_capture(out).meta


def test_euroc_unix_stamps_give_the_capture_its_date(tmp_path):
    """EuRoC's stamps are Unix ns (MH_01 starts 2014-06-24 19:02:59 UTC): now the capture's date."""
    t, w, a = _imu_rows(np.random.default_rng(3))
    src = _write_imu_csv(tmp_path / "data.csv", EUROC, t, w, a)
    out = tmp_path / "o.csv"
    res = run_station("import", src, "--procedure", "gyro-drift", "--out", out)
    assert res.returncode == 0, res.stderr
    cap = read_capture(out)
    assert cap.meta["date"] == "2014-06-24T19:02:59" and cap.columns["t"][0] == 0
