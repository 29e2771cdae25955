"""`station import` of plain CSV and text files as the world's writers write them (QA s26d).

Every file here is made by the writer named, not by hand: pandas ``DataFrame.to_csv`` (its
default index and the numbered columns of a numpy array; ``sep=';', decimal=','`` as a German
spreadsheet export), ``numpy.savetxt`` (its ``header=`` is a ``# `` comment line), Python's
``csv`` module (dialects ``excel`` and ``excel-tab``, a units row under the header, a BOM,
``QUOTE_ALL``), LibreOffice's own CSV export of an .xlsx it wrote (skipped without
``soffice``). The rows are the real imucal Ferraris session (``shared/data/imucal_ferraris``:
m/s², deg/s, 102.4 Hz); the MPU-6050 logger's counts (``shared/data/mpu6050_unc``) for the
thousands separators. MATLAB cannot run here: its ``writematrix`` output is written as its
documentation describes it (comma-delimited, no header, ``longG``: 15 significant digits, CRLF
on Windows).
"""

from __future__ import annotations

import csv
import os
import shutil
import subprocess

import numpy as np
import pytest

from station.capture import read_capture
from tests.station_run import assert_one_line_refusal, run_station

SHARED = os.environ.get("STATION_SHARED") or os.path.join(os.path.dirname(__file__), "..", "..", "shared")
FERRARIS = os.path.join(SHARED, "data", "imucal_ferraris", "original", "example_ferraris_session.csv")
MPU6050 = os.path.join(SHARED, "data", "mpu6050_unc", "original", "example_data_calibration.csv")
needs_data = pytest.mark.skipif(not os.path.exists(FERRARIS), reason="../shared/data is not beside this clone")
RATE_HZ = 102.4  # imucal_ferraris/SOURCE.md
N_ROWS = 2000  # the session's first 20 s: enough to read, quick to import
UNITS = ["--unit", "accel=m/s^2,gyro=deg/s"]


@pytest.fixture(scope="module")
def session():
    """The imucal session's first rows: t (s, from its sample numbers at 102.4 Hz), acc (m/s²), gyr (deg/s)."""
    import pandas as pd

    f = pd.read_csv(FERRARIS).head(N_ROWS)
    t = f["n_samples"].to_numpy() / RATE_HZ
    return t, f[["acc_x", "acc_y", "acc_z"]].to_numpy(), f[["gyr_x", "gyr_y", "gyr_z"]].to_numpy()


def _import(tmp_path, src, *args, procedure="accel-tabletop"):
    out = tmp_path / f"{src.name}.capture.csv"
    res = run_station("import", src, "--procedure", procedure, "--out", out, *args)
    return res, out


def _imported(tmp_path, src, *args):
    res, out = _import(tmp_path, src, *args)
    assert res.returncode == 0, res.stderr
    assert res.stdout.startswith(f"{out}: accel-tabletop, {N_ROWS} rows"), res.stdout
    return read_capture(out), res.stderr


def _same_accel(capture, session, t=True):
    t_s, acc, _ = session
    for j, c in enumerate(("ax", "ay", "az")):
        np.testing.assert_allclose(capture.columns[c], acc[:, j], rtol=1e-12, atol=0)
    if t:
        np.testing.assert_allclose(capture.columns["t"], t_s, rtol=0, atol=1e-9)


# ---------------------------------------------------------------- (a) ';' with decimal commas


@needs_data
@pytest.mark.parametrize("sep", [";", "\t"], ids=["semicolon", "tab"])
def test_a_headerless_file_with_decimal_commas_is_split_at_its_own_delimiter(tmp_path, session, sep):
    """pandas to_csv(header=False, index=False, sep=';', decimal=',') as a German spreadsheet
    export writes it: '0,0;10,33...;-0,57...'. Before: split at its commas ("column 'ax':
    '0;10' is not a number"); the delimiter was sniffed ',' first. Now ';' (or a tab) outside
    quotes is the delimiter and the commas are decimal marks."""
    import pandas as pd

    t, acc, _ = session
    src = tmp_path / "de.csv"
    pd.DataFrame(np.column_stack([t, acc])).to_csv(src, header=False, index=False, sep=sep, decimal=",")
    assert src.read_text().startswith(f"0,0{sep}10,33")
    capture, stderr = _imported(tmp_path, src, "--map", "t=1,ax=2,ay=3,az=4", *UNITS)
    _same_accel(capture, session)
    assert stderr == ""


# --------------------------------------------------------------- (b) numbered channels as a header


@needs_data
@pytest.mark.parametrize(
    "write, first_line",
    [
        (lambda f, p: f.to_csv(p), ",0,1,2"),  # pandas' defaults: its index, then the array's column numbers
        (lambda f, p: f.to_csv(p, index=False), "0,1,2"),
    ],
    ids=["pandas-default-index", "pandas-index-false"],
)
def test_pandas_numbered_columns_are_its_header_and_map_by_their_names(tmp_path, session, write, first_line):
    """pd.DataFrame(array).to_csv(): header ',0,1,2' (or '0,1,2'). Before: ',0,1,2' was 'no
    header row: this line holds 4 numbers', and with --map by numbers it was read as a data row
    (a sample ax=0, ay=1, az=2 m/s² among the real ones, without a word). Now it is the header,
    said; --map ax=0,... names its columns as pandas numbered them, said too."""
    import pandas as pd

    _, acc, _ = session
    src = tmp_path / "array.csv"
    write(pd.DataFrame(acc), src)
    assert src.read_text().splitlines()[0] == first_line
    capture, stderr = _imported(tmp_path, src, "--map", "ax=0,ay=1,az=2", "--rate", str(RATE_HZ), *UNITS)
    _same_accel(capture, session, t=False)
    assert f"line 1 ('{first_line}') is read as a header of numbered columns" in stderr, stderr
    assert stderr.count("\n") == 2 and "--map ax=0 (column" in stderr, stderr


@needs_data
def test_a_time_column_beside_numbered_channels_is_a_header(tmp_path, session):
    """pandas' to_csv of a frame whose columns are 'time' and an array's 0, 1, 2. Before:
    --map t=time,ax=0,... ended in "cannot process this input (StopIteration)", and --map by
    numbers in "column 't': 'time' is not a number"."""
    import pandas as pd

    t, acc, _ = session
    frame = pd.DataFrame(acc)
    frame.insert(0, "time", t)
    src = tmp_path / "time012.csv"
    frame.to_csv(src, index=False)
    assert src.read_text().startswith("time,0,1,2\n")
    capture, stderr = _imported(tmp_path, src, "--map", "t=time,ax=0,ay=1,az=2", *UNITS)
    _same_accel(capture, session)
    assert stderr.count("\n") == 1 and "the header's column names, not column numbers" in stderr, stderr
    # the numbers counted as positions clash with the names: refused, saying how they were read
    (tmp_path / f"{src.name}.capture.csv").unlink()
    res, out = _import(tmp_path, src, "--map", "t=1,ax=2,ay=3,az=4", *UNITS)
    # (s28: said as a row whose field 1 is no number, or pandas' header --map's numbers do not name)
    assert_one_line_refusal(res, f"{src}:1: field 1: 'time' is not a number", "(--map ax=0,...)")
    assert not out.exists()


def test_a_data_row_of_whole_numbers_from_zero_is_still_data_and_said(tmp_path):
    """'0,1,2' over rows of whole numbers (a counter and counts) stays a data row, said in one
    line, since pandas' to_csv(index=False) of an integer array writes the same; --map by
    those numbers (ax=0: no column's position) reads it as that header."""
    src = tmp_path / "ints.csv"
    src.write_text("0,1,2\n" + "".join(f"{k},{k + 1},{k + 2}\n" for k in range(1, 20)))
    args = ("--rate", "100", "--unit", "accel=counts")
    res, out = _import(tmp_path, src, "--map", "ax=1,ay=2,az=3", *args)
    assert res.returncode == 0 and res.stderr.count("\n") == 1, res.stderr
    assert "line 1 ('0,1,2') is read as data, though its numbers run as pandas' to_csv" in res.stderr
    assert read_capture(out).columns["ax"][0] == 0.0 and read_capture(out).n_rows == 20
    res, out = _import(tmp_path, src, "--map", "ax=0,ay=1,az=2", *args)
    assert res.returncode == 0, res.stderr
    assert read_capture(out).columns["ax"][0] == 1.0 and read_capture(out).n_rows == 19


# ------------------------------------------------------------- (c) unknown columns are said


@needs_data
def test_columns_no_capture_has_are_said_in_one_line(tmp_path, session):
    """A csv.writer file with the capture's names and two more ('tmperature_C', 'axx'), read
    without --map. Before: imported, the two dropped without a word."""
    t, acc, _ = session
    src = tmp_path / "extra.csv"
    with open(src, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["t", "ax", "ay", "az", "tmperature_C", "axx"])
        w.writerows(np.column_stack([t, acc, np.full(len(t), 25.0), acc[:, 0]]).tolist())
    capture, stderr = _imported(tmp_path, src, *UNITS)
    _same_accel(capture, session)
    assert stderr.count("\n") == 1, stderr
    assert (
        "line 1: columns 'tmperature_C' (did you mean 'temp_c'?), 'axx' (did you mean 'ax'?): no capture column"
        in stderr
    ), stderr


@needs_data
def test_a_time_series_capture_with_an_unknown_column_warns_once(tmp_path):
    """The imucal capture with a 'tmperature_C' column added by the csv module. Tables of
    averages already warned; a time series said nothing (calibrate, inspect: stderr empty)."""
    src = os.path.join(SHARED, "data", "imucal_ferraris", "imucal_ferraris.capture.csv")
    lines = open(src).read().splitlines()
    meta = [ln for ln in lines if ln.startswith("#")]
    rows = list(csv.reader(ln for ln in lines if not ln.startswith("#")))
    path = tmp_path / "extra.capture.csv"
    with open(path, "w", newline="") as fh:
        fh.write("\n".join(meta) + "\n")
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(rows[0] + ["tmperature_C"])
        w.writerows(r + ["25.0"] for r in rows[1:])
    res = run_station("inspect", path)
    assert res.returncode == 0, res.stderr
    said = f"line {len(meta) + 1}: column 'tmperature_C' (did you mean 'temp_c'?) of this time series: no column of a capture"
    assert res.stderr.count("\n") == 1 and said in res.stderr, res.stderr


# ------------------------------------------------------- numpy.savetxt, units rows, separators


@needs_data
@pytest.mark.parametrize(
    "delimiter, header",
    [(" ", "t ax ay az"), ("\t", "t\tax\tay\taz"), (",", "t,ax,ay,az")],
    ids=["space", "tab", "comma"],
)
def test_numpy_savetxt_header_is_the_header(tmp_path, session, delimiter, header):
    """np.savetxt(..., header=...) writes '# t ax ay az' above the numbers, which
    np.genfromtxt(names=True) reads as the names. Before: the comment was skipped and the
    first data row refused, 'no header row: this line holds 4 numbers'."""
    t, acc, _ = session
    src = tmp_path / "saved.txt"
    np.savetxt(src, np.column_stack([t, acc]), delimiter=delimiter, header=header)
    assert src.read_text().startswith(f"# {header}\n")
    capture, stderr = _imported(tmp_path, src, *UNITS)
    _same_accel(capture, session)
    assert stderr == ""


@needs_data
def test_a_units_row_under_the_header_gives_the_units(tmp_path, session):
    """'t,ax,ay,az' then 's,m/s^2,m/s^2,m/s^2' (csv.writer). Before: "line 2: column 't': 's'
    is not a number". Now the row is read as the units: no --unit needed; a --unit that differs
    is used and said; a sensor's columns in two units are refused on that line."""
    t, acc, _ = session

    def write(name, units_row):
        path = tmp_path / name
        with open(path, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["t", "ax", "ay", "az"])
            w.writerow(units_row)
            w.writerows(np.column_stack([t, acc]).tolist())
        return path

    src = write("units.csv", ["s", "m/s^2", "m/s^2", "m/s^2"])
    capture, stderr = _imported(tmp_path, src)
    _same_accel(capture, session)
    assert capture.meta["accel_unit"] == "m/s^2" and stderr == ""
    res, out = _import(tmp_path, src, "--unit", "accel=g")
    assert res.returncode == 0 and res.stderr.count("\n") == 1, res.stderr
    assert "--unit accel=g differs from the units row (line 2: 'm/s^2'" in res.stderr
    ms = write("ms.csv", ["[ms]", "[m/s^2]", "[m/s^2]", "[m/s^2]"])
    capture, _ = _imported(tmp_path, ms)
    np.testing.assert_allclose(capture.columns["t"], t * 1e-3, rtol=0, atol=1e-9)  # the capture keeps 1 ns
    mixed = write("mixed.csv", ["s", "m/s^2", "g", "m/s^2"])
    res, out = _import(tmp_path, mixed)
    assert_one_line_refusal(res, f"{mixed}:2: units row: the accelerometer columns ax, ay, az are in different units")
    assert not out.exists()


@pytest.mark.skipif(not os.path.exists(MPU6050), reason="../shared/data is not beside this clone")
def test_thousands_separators_are_refused_saying_so(tmp_path):
    """The MPU-6050 logger's counts written as a spreadsheet shows them with its 1000 separator
    (csv.writer quotes '15,032'). Before: "'15,032' is not a number" and no word why."""
    import pandas as pd

    m = pd.read_csv(MPU6050, skiprows=4)  # its preamble (Fs,100 ...) left out
    src = tmp_path / "thousands.csv"
    with open(src, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(list(m.columns))
        w.writerows([f"{v:,}" for v in r] for r in m.to_numpy().tolist())
    res, out = _import(tmp_path, src, "--rate", "100", "--unit", "accel=counts,gyro=counts")
    assert_one_line_refusal(res, f"{src}:2: column 'az': '15,032' is not a number: a thousands separator?")
    assert not out.exists()


# ------------------------------------------------------------------- writers read as they are


def _matlab_writematrix(path, a):
    """What MATLAB's writematrix(A, 'f.csv') writes per its documentation: comma-delimited, no
    header, each number in 'longG' (15 significant digits), CRLF line ends (Windows)."""
    path.write_bytes("".join(",".join(f"{x:.15g}" for x in row) + "\r\n" for row in a.tolist()).encode())


@needs_data
@pytest.mark.parametrize(
    "writer", ["excel", "excel-tab", "bom", "quote-all", "trailing-delimiter", "matlab-writematrix"]
)
def test_other_writers_read_as_the_same_numbers(tmp_path, session, writer):
    t, acc, gyr = session
    data = np.column_stack([t, acc, gyr])
    names = ["t", "ax", "ay", "az", "gx", "gy", "gz"]
    src = tmp_path / f"{writer}.csv"
    args = list(UNITS)
    if writer == "matlab-writematrix":
        _matlab_writematrix(src, data)
        args += ["--map", "t=1,ax=2,ay=3,az=4,gx=5,gy=6,gz=7"]
    else:
        kw = {
            "excel": dict(dialect="excel"),
            "excel-tab": dict(dialect="excel-tab"),
            "bom": dict(),
            "quote-all": dict(quoting=csv.QUOTE_ALL),
            "trailing-delimiter": dict(),
        }[writer]
        with open(src, "w", newline="", encoding="utf-8-sig" if writer == "bom" else "utf-8") as fh:
            w = csv.writer(fh, **kw)
            pad = [""] if writer == "trailing-delimiter" else []
            w.writerow(names + pad)
            w.writerows(r + pad for r in data.tolist())
    capture, stderr = _imported(tmp_path, src, *args)
    _same_accel(capture, session)
    np.testing.assert_allclose(
        capture.columns["gz"], gyr[:, 2], rtol=1e-12 if writer != "matlab-writematrix" else 1e-14
    )
    assert stderr == ""


@needs_data
@pytest.mark.skipif(shutil.which("soffice") is None, reason="LibreOffice (soffice) is not installed")
def test_libreoffice_csv_export_of_an_xlsx_it_wrote(tmp_path, session):
    """LibreOffice reads a CSV, saves it as .xlsx, then exports that .xlsx as CSV with ';' as the
    field separator (its filter options 59,34,76: ';', '"', UTF-8)."""
    import pandas as pd

    t, acc, gyr = session
    src = tmp_path / "in.csv"
    pd.DataFrame({"t": t, "ax": acc[:, 0], "ay": acc[:, 1], "az": acc[:, 2]}).to_csv(src, index=False)
    profile = f"-env:UserInstallation=file://{tmp_path / 'lo-profile'}"
    for target, infile, outdir in (
        ("xlsx", src, tmp_path / "xlsx"),
        ("csv:Text - txt - csv (StarCalc):59,34,76,1", tmp_path / "xlsx" / "in.xlsx", tmp_path / "csv"),
    ):
        done = subprocess.run(
            ["soffice", profile, "--headless", "--convert-to", target, "--outdir", str(outdir), str(infile)],
            capture_output=True,
            text=True,
            timeout=180,
        )
        assert done.returncode == 0, done.stderr
    exported = tmp_path / "csv" / "in.csv"
    assert exported.read_text().startswith('"t";"ax";"ay";"az"\n')  # its text cells quoted
    capture, stderr = _imported(tmp_path, exported, *UNITS)
    _same_accel(capture, session)
    assert stderr == ""


@needs_data
@pytest.mark.parametrize("zone", [None, "Europe/Berlin"], ids=["naive", "tz-aware"])
def test_a_time_column_of_dates_and_times_as_pandas_writes_a_datetime_index(tmp_path, session, zone):
    """A logger's frame indexed by pd.to_datetime (naive, or tz_convert'ed: pandas writes
    '2024-03-01 01:00:00.009765625+01:00'). Before: "column 't': '2024-03-01 00:00:00' is not
    a number". Now t is read to the ns, from 0, and the first gives the capture's date in UTC
    (a time without a zone is read as UTC, said)."""
    import pandas as pd

    t, acc, _ = session
    stamps = pd.DatetimeIndex(pd.to_datetime(t * 1e9, unit="ns", origin="2024-03-01"))
    if zone:
        stamps = stamps.tz_localize("UTC").tz_convert(zone)
    frame = pd.DataFrame({"ax": acc[:, 0], "ay": acc[:, 1], "az": acc[:, 2]}, index=stamps.rename("t"))
    src = tmp_path / "stamped.csv"
    frame.to_csv(src)
    assert (
        src.read_text()
        .splitlines()[1]
        .startswith("2024-03-01 01:00:00.000000000+01:00," if zone else "2024-03-01 00:00:00.000000000,")
    )
    capture, stderr = _imported(tmp_path, src, *UNITS)
    _same_accel(capture, session)
    assert capture.meta["date"] == "2024-03-01T00:00:00"
    if zone:
        assert stderr == ""
    else:
        assert stderr.count("\n") == 1 and "have no time zone" in stderr, stderr
    res, out = _import(tmp_path, src, "--unit", "accel=m/s^2,t=ms")
    assert_one_line_refusal(res, "--unit t=ms: the time column holds dates and times")
    lines = src.read_text().splitlines(keepends=True)
    lines[5] = "not a time" + lines[5][lines[5].index(",") :]
    bad = tmp_path / "bad.csv"
    bad.write_text("".join(lines))
    res, out = _import(tmp_path, bad, *UNITS)
    assert_one_line_refusal(res, f"{bad}:6: column 't': 'not a time' is not a date and time")
