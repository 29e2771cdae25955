"""Files as the world writes them, through `import`, `inspect`, `calibrate`, `diagnose` (QA s27i).

- Excel's ``sep=;`` first line names the delimiter (Excel writes it, and reads it, where the
  locale's list separator would leave a file ambiguous): before, it was warned about as a
  line "above the header".
- A corrupt first row of a headerless file that ends in small whole numbers (``x1.5,0,1,2``,
  ``abc,1,2,3``) was read as pandas' header of numbered columns (``,0,1,2``) and --map's
  numbers then named its columns: another column's samples imported, with a warning only.
- Unknown columns are said with the capture column they most likely mean (``tmperature_C``:
  ``temp_c``), their unit left out and the names loggers use (``acc_x``, ``gyr_z``) known.
- A station capture Excel saved as Windows-1252 (a metadata line with '°', 'ü') or as UTF-16
  with a byte-order mark is read as ``station import`` reads them (one decision,
  ``station.textencoding.text_encoding``); one that no encoding reads is refused in one line saying what to
  do, by ``inspect`` and ``import`` alike.

The rows are real: the imucal Ferraris session and Wang & Li's centrifuge table
(``shared/data``); the files are written by pandas, the csv module and Python's own encoders.
"""

from __future__ import annotations

import csv
import json
import os

import numpy as np
import pytest

from station.capture import read_capture
from tests.station_run import assert_one_line_refusal, run_station

SHARED = os.environ.get("STATION_SHARED") or os.path.join(os.path.dirname(__file__), "..", "..", "shared")
FERRARIS = os.path.join(SHARED, "data", "imucal_ferraris", "original", "example_ferraris_session.csv")
TABLE1 = os.path.join(SHARED, "data", "wang2021_centrifuge", "table1.capture.csv")
pytestmark = pytest.mark.skipif(not os.path.exists(FERRARIS), reason="../shared/data is not beside this clone")
RATE_HZ = 102.4  # imucal_ferraris/SOURCE.md
N_ROWS = 500
UNITS = ["--unit", "accel=m/s^2,gyro=deg/s"]


@pytest.fixture(scope="module")
def session():
    import pandas as pd

    f = pd.read_csv(FERRARIS).head(N_ROWS)
    return f["n_samples"].to_numpy() / RATE_HZ, f[["acc_x", "acc_y", "acc_z"]].to_numpy()


def _import(tmp_path, src, *args):
    out = tmp_path / f"{src.name}.capture.csv"
    return run_station("import", src, "--procedure", "accel-tabletop", "--out", out, *args), out


# ------------------------------------------------------------------------------ 1. sep=;


@pytest.mark.parametrize("sep", [";", "\t", ","], ids=["semicolon", "tab", "comma"])
def test_excels_sep_line_names_the_delimiter_and_is_no_preamble(tmp_path, session, sep):
    """pandas to_csv(sep=..., decimal=',' where ';' or a tab) under Excel's 'sep=X' line.
    Before: 'lines 1-1 above the header (line 2) are not data: skipped (line 1: 'sep=;')'."""
    import pandas as pd

    t, acc = session
    frame = pd.DataFrame({"t": t, "ax": acc[:, 0], "ay": acc[:, 1], "az": acc[:, 2]})
    src = tmp_path / "excel.csv"
    with open(src, "w", newline="") as fh:
        fh.write(f"sep={sep}\r\n")
        frame.to_csv(fh, sep=sep, decimal="," if sep != "," else ".", index=False, lineterminator="\r\n")
    res, out = _import(tmp_path, src, *UNITS)
    assert res.returncode == 0, res.stderr
    assert res.stderr == ""
    capture = read_capture(out)
    np.testing.assert_allclose(capture.columns["ax"], acc[:, 0], rtol=1e-12, atol=0)
    np.testing.assert_allclose(capture.columns["t"], t, rtol=0, atol=1e-9)


def test_a_sep_line_over_nothing_is_an_empty_file(tmp_path):
    src = tmp_path / "empty.csv"
    src.write_text("sep=;\n\n")
    res, out = _import(tmp_path, src, *UNITS)
    assert_one_line_refusal(res, f"{src}:1: empty file: no header row under its 'sep=;' line")
    assert not out.exists()


# ------------------------------------------------------- 2. a corrupt row is no numbered header


@pytest.mark.parametrize("first", ["x1.5,0,1,2,3", "abc,1,2,3,4", "a,b,0,1,2", "9.81e,0,1,2,3"])
def test_a_corrupt_first_row_ending_in_whole_numbers_is_refused_on_its_line(tmp_path, session, first):
    """A headerless file (pandas, header=False) of t, ax, ay, az and a counter, its first row
    corrupt. Before: read as pandas' numbered header, --map ax=1,ay=2,az=3 then named the
    columns '1', '2', '3' (ay, az and the counter imported as ax, ay, az), with a warning only."""
    import pandas as pd

    t, acc = session
    src = tmp_path / "headerless.csv"
    pd.DataFrame(np.column_stack([acc, np.arange(len(t)) % 7])).to_csv(src, header=False, index=False)
    src.write_text(first + "\n" + src.read_text().split("\n", 1)[1])
    res, out = _import(tmp_path, src, "--map", "ax=1,ay=2,az=3", "--rate", str(RATE_HZ), *UNITS)
    bad = next(c for c in first.split(",") if c and not c.replace(".", "").isdigit())
    assert_one_line_refusal(res, f"{src}:1: column 'ax': '{bad}' is not a number")
    assert not out.exists()


@pytest.mark.parametrize("first", [",0,1,2", "time,0,1,2", "Unnamed: 0,0,1,2", "imu1_time (s),0,1,2"])
def test_pandas_numbered_headers_are_still_headers(tmp_path, session, first):
    """The headers pandas writes (its index unnamed, named, or read back and written again)."""
    import pandas as pd

    t, acc = session
    src = tmp_path / "numbered.csv"
    frame = pd.DataFrame(acc)
    frame.index = t
    frame.to_csv(src)
    src.write_text(first + "\n" + src.read_text().split("\n", 1)[1])
    res, out = _import(tmp_path, src, "--map", "ax=0,ay=1,az=2", "--rate", str(RATE_HZ), *UNITS)
    assert res.returncode == 0, res.stderr
    np.testing.assert_allclose(read_capture(out).columns["ay"], acc[:, 1], rtol=1e-12, atol=0)


# ------------------------------------------------------------------ 3. the nearest column name


def test_unknown_columns_are_said_with_the_capture_column_they_mean(tmp_path, session):
    """csv.writer with a logger's names beside the capture's t. Before: 'tmperature_C',
    'acc_x_mps2' and 'gyr_z' were said with no hint (difflib over the bare capture names only)."""
    t, acc = session
    src = tmp_path / "logger.csv"
    with open(src, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["t", "ax", "ay", "az", "tmperature_C", "acc_x_mps2", "Gyr Z (deg/s)", "pressure_hPa"])
        w.writerows(np.column_stack([t, acc, np.full(len(t), 25.0), acc[:, 0], acc[:, 2], np.full(len(t), 1013.0)]))
    res, out = _import(tmp_path, src, *UNITS)
    assert res.returncode == 0 and res.stderr.count("\n") == 1, res.stderr
    said = (
        "line 1: columns 'tmperature_C' (did you mean 'temp_c'?), 'acc_x_mps2' (did you mean 'ax'?), "
        "'Gyr Z (deg/s)' (did you mean 'gz'?), 'pressure_hPa': no capture column"
    )
    assert said in res.stderr, res.stderr


# ------------------------------------------------- 4. a capture Excel saved in another encoding


def _table(tmp_path, name, encoding, newline="\n"):
    """Wang & Li's Table 1 capture with a line a bench sheet holds ('°', 'ü': no ASCII), saved
    in ``encoding`` by Python's own encoder."""
    text = open(TABLE1, encoding="utf-8").read()
    text = text.replace("# source:", "# operator: Jürgen Weiß, 23 °C, ±0.5 µm\n# source:", 1)
    path = tmp_path / name
    with open(path, "w", encoding=encoding, newline=newline) as fh:
        fh.write(text)
    return path


def _result(res):
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout)


@pytest.mark.parametrize(
    "encoding, newline, note",
    [
        ("cp1252", "\r\n", "not UTF-8 (byte 0xfc on line 8): read as Windows-1252"),
        ("utf-16", "\r\n", None),  # Python's 'utf-16' writes the mark, little-endian here
        ("utf-16-be", "\n", None),
    ],
    ids=["windows-1252", "utf-16", "utf-16-be"],
)
def test_a_capture_saved_in_another_encoding_is_read_as_import_reads_it(tmp_path, encoding, newline, note):
    """Before: inspect said 'not UTF-8 text: byte 0xfc at column 16' (or 'UTF-16 text;
    capture files are UTF-8'), while import said 'already a station capture: ... read it as
    it is'. Now calibrate, diagnose and inspect read it, the same numbers as the UTF-8 file."""
    utf8 = _table(tmp_path, "utf8.capture.csv", "utf-8")
    path = _table(tmp_path, f"{encoding}.capture.csv", encoding, newline)
    if encoding == "utf-16-be":  # with its mark, as Excel writes 'Unicode Text' big-endian
        path.write_bytes(b"\xfe\xff" + path.read_bytes())
    want = _result(run_station("calibrate", utf8, "--json"))
    res = run_station("calibrate", path, "--json")
    got = _result(res)
    assert got["params"] == want["params"]
    if note is None:
        assert res.stderr == ""
    else:
        assert res.stderr.count("\n") == 1 and f"station: {path}: warning: {note}" in res.stderr, res.stderr
    res = run_station("inspect", path)
    assert res.returncode == 0 and "operator" in res.stdout and (note is None) == (res.stderr == ""), res.stderr
    assert "Jürgen Weiß, 23 °C" in read_capture(path).meta["operator"]
    res = run_station("import", path, "--procedure", "accel-tabletop", "--out", tmp_path / "x.csv")
    assert_one_line_refusal(res, f"{path}:1: already a station capture: calibrate, diagnose and inspect read it")


def test_a_capture_no_encoding_reads_is_refused_alike_by_inspect_and_import(tmp_path):
    """A byte that is no Windows-1252 character either (0x81) in a metadata line. Before:
    inspect refused it, import said it was already a capture that inspect reads."""
    path = _table(tmp_path, "bad.capture.csv", "cp1252")
    path.write_bytes(path.read_bytes().replace(b"\xfc", b"\x81", 1))
    said = f"{path}:8: not UTF-8 text: byte 0x81 (nor a Windows-1252 character): save the file as UTF-8"
    assert_one_line_refusal(run_station("inspect", path), said)
    assert_one_line_refusal(run_station("calibrate", path, "--json"), said)
    out = tmp_path / "x.csv"
    assert_one_line_refusal(run_station("import", path, "--procedure", "accel-tabletop", "--out", out), said)
    assert not out.exists()


# ------------------------------------------------------------- a spreadsheet's padded blank rows


def test_blank_rows_padded_to_the_tables_width_are_blank(tmp_path, session):
    """csv.writer of a sheet whose first rows are empty (Excel and LibreOffice write the used
    range: ',,,' for an empty row). Before: 'line 1: no header row: this line holds 4 numbers'."""
    t, acc = session
    src = tmp_path / "padded.csv"
    with open(src, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerows([["", "", "", ""], ["", "", "", ""], ["t", "ax", "ay", "az"]])
        w.writerows(np.column_stack([t, acc]).tolist())
    assert src.read_bytes().startswith(b",,,\r\n")
    res, out = _import(tmp_path, src, *UNITS)
    assert res.returncode == 0 and res.stderr == "", res.stderr
    np.testing.assert_allclose(read_capture(out).columns["az"], acc[:, 2], rtol=1e-12, atol=0)
    only = tmp_path / "only.csv"
    with open(only, "w", newline="") as fh:
        csv.writer(fh).writerows([["", "", "", ""]] * 3)
    res, out = _import(tmp_path, only, *UNITS)
    assert_one_line_refusal(res, f"{only}:1: empty file: no header row")


def test_a_capture_that_cannot_be_copied_as_utf8_is_refused_in_one_line(tmp_path):
    """The UTF-8 copy a Windows-1252 capture is read through, where no file may grow past
    64 KiB (the OS's own limit, RLIMIT_FSIZE: as a full disk stops the write). Before the
    copy's write was told from its read: 'cannot read: File too large', of the wrong file."""
    import resource
    import signal
    import subprocess
    import sys

    text = open(os.path.join(SHARED, "data", "imucal_ferraris", "imucal_ferraris.capture.csv"), encoding="utf-8").read()
    path = tmp_path / "big.capture.csv"
    path.write_bytes(text.replace("# device:", "# operator: Jürgen\n# device:", 1).encode("cp1252"))
    assert path.stat().st_size > 4 * 65536

    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails (EFBIG), not the process
        resource.setrlimit(resource.RLIMIT_FSIZE, (65536, 65536))

    res = subprocess.run(
        [sys.executable, "-m", "station", "inspect", str(path)],
        capture_output=True,
        text=True,
        timeout=120,
        preexec_fn=limit,
        env={**os.environ, "TMPDIR": str(tmp_path)},
    )
    assert_one_line_refusal(
        res, f"{path}: Windows-1252 text, read through a UTF-8 copy that could not be made (File too large)"
    )
    assert [p.name for p in tmp_path.iterdir()] == ["big.capture.csv"]  # the temporary copy removed


def test_a_file_with_no_capture_column_is_told_the_map_its_names_suggest(tmp_path):
    """The imucal session as its authors wrote it (n_samples, gyr_x, ..., acc_z), imported
    without --map. Before: the fixed example '--map t=time,ax=acc_x,ay=acc_y,az=acc_z', which
    names columns this file does not have; now the --map its own names suggest."""
    out = tmp_path / "x.capture.csv"
    res = run_station("import", FERRARIS, "--procedure", "accel-tabletop", "--out", out)
    assert_one_line_refusal(
        res, "say which is which with --map, e.g. --map ax=acc_x,ay=acc_y,az=acc_z,gx=gyr_x,gy=gyr_y,gz=gyr_z"
    )
    assert not out.exists()


def test_a_capture_saved_as_excels_unicode_text_says_to_save_it_as_csv(tmp_path):
    """Excel opens a capture as a table (each line split at its commas) and saves it as
    "Unicode Text": UTF-16 with a mark, the cells joined by tabs (csv's excel-tab dialect, as
    Excel writes it). Before: 'a capture's metadata cannot hold a control character (a tab,
    ...)', with no word of what to do; now read as UTF-16, the tabs said, and what to save."""
    rows = list(csv.reader(open(TABLE1, encoding="utf-8")))
    path = tmp_path / "unicode.capture.txt"
    with open(path, "w", encoding="utf-16", newline="") as fh:
        csv.writer(fh, dialect="excel-tab").writerows(rows)
    line = next(k for k, r in enumerate(rows, 1) if r[0].startswith("# source"))
    res = run_station("inspect", path)
    assert_one_line_refusal(
        res, f"{path}:{line}: metadata 'source'", "tabs where the line had commas? A capture is comma-separated: save"
    )


def test_a_loggers_channels_numbered_from_1_are_a_header_when_map_names_its_time(tmp_path, session):
    """csv.writer of 'time,1,2,3' (a logger numbering its channels from 1) over the imucal rows,
    with --map t=time,ax=1,...: the line holds the column --map names, so it is the header
    (as before this session's stricter numbered header; a guard, not a fix)."""
    t, acc = session
    src = tmp_path / "logger.csv"
    with open(src, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["time", "1", "2", "3"])
        w.writerows(np.column_stack([t, acc]).tolist())
    res, out = _import(tmp_path, src, "--map", "t=time,ax=1,ay=2,az=3", *UNITS)
    assert res.returncode == 0, res.stderr
    np.testing.assert_allclose(read_capture(out).columns["ax"], acc[:, 0], rtol=1e-12, atol=0)
