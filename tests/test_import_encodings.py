"""`station import` of a plain CSV as Excel on Windows saves it (QA s26g).

"CSV (Comma delimited)" is Windows-1252 (a header ``Temp (°C)`` holds the byte 0xb0, ``µT``
0xb5), "Unicode Text" is UTF-16 LE with a byte-order mark, tab-separated. Both were refused
("not UTF-8 text: byte 0xb0", "UTF-16 text; CSV files are read as UTF-8"). The files are made
by the real encoders (``str.encode``, pandas ``to_csv(encoding=...)``) from the real imucal
Ferraris session (``shared/data/imucal_ferraris``); each import is checked against the same
text saved as UTF-8, value for value, and read back by ``station inspect``.
"""

from __future__ import annotations

import codecs
import os

import numpy as np
import pytest

from station.capture import read_capture
from tests.station_run import assert_one_line_refusal, run_station

SHARED = os.environ.get("STATION_SHARED") or os.path.join(os.path.dirname(__file__), "..", "..", "shared")
FERRARIS = os.path.join(SHARED, "data", "imucal_ferraris", "original", "example_ferraris_session.csv")
pytestmark = pytest.mark.skipif(not os.path.exists(FERRARIS), reason="../shared/data is not beside this clone")
RATE_HZ = 102.4  # imucal_ferraris/SOURCE.md
N_ROWS = 500  # the session's first ~5 s: enough to read, quick to import
# names as a bench engineer's sheet has them: '°' and '²' are no ASCII (0xb0, 0xb2 in Windows-1252)
NAMES = ["Time (s)", "Acc X (m/s²)", "Acc Y (m/s²)", "Acc Z (m/s²)", "Gyr X (°/s)", "Gyr Y (°/s)", "Gyr Z (°/s)"]
MAP = ["--map", ",".join(f"{c}={n}" for c, n in zip(("t", "ax", "ay", "az", "gx", "gy", "gz"), NAMES))]
UNITS = ["--unit", "accel=m/s^2,gyro=deg/s,t=s"]


@pytest.fixture(scope="module")
def frame():
    """The session's first rows under the sheet's names: time (s), acc (m/s²), gyr (deg/s)."""
    import pandas as pd

    f = pd.read_csv(FERRARIS).head(N_ROWS)
    out = pd.DataFrame({NAMES[0]: f["n_samples"] / RATE_HZ})
    for name, col in zip(NAMES[1:], ("acc_x", "acc_y", "acc_z", "gyr_x", "gyr_y", "gyr_z")):
        out[name] = f[col]
    return out


def _import(tmp_path, src):
    out = tmp_path / f"{src.name}.capture.csv"
    return run_station("import", src, "--procedure", "accel-tabletop", *MAP, *UNITS, "--out", out), out


def _same_as_utf8(tmp_path, frame, src, sep=","):
    """``src`` imported equals the frame saved as UTF-8 and imported, value for value; both
    read back by `station inspect` alike. The stderr of ``src``'s import."""
    ref = tmp_path / "utf8.csv"
    frame.to_csv(ref, index=False, sep=sep, encoding="utf-8")
    res_ref, out_ref = _import(tmp_path, ref)
    assert res_ref.returncode == 0, res_ref.stderr
    res, out = _import(tmp_path, src)
    assert res.returncode == 0, res.stderr
    assert res.stdout.startswith(f"{out}: accel-tabletop, {N_ROWS} rows"), res.stdout
    got, want = read_capture(out), read_capture(out_ref)
    assert set(got.columns) == set(want.columns) == {"t", "ax", "ay", "az", "gx", "gy", "gz"}
    for c in want.columns:
        np.testing.assert_array_equal(got.columns[c], want.columns[c], err_msg=c)
    shown, shown_ref = run_station("inspect", out), run_station("inspect", out_ref)
    assert shown.returncode == 0 and shown.stderr == "", shown.stderr
    assert shown.stdout.replace(str(out), "X") == shown_ref.stdout.replace(str(out_ref), "X")
    return res.stderr


@pytest.mark.parametrize("writer", ["str.encode", "pandas"])
def test_a_windows_1252_csv_is_read_as_such_and_said(tmp_path, frame, writer):
    """Excel's "CSV (Comma delimited)": was 'not UTF-8 text: byte 0xb2'. Now read as
    Windows-1252, one warning line naming the file, the byte and its line."""
    src = tmp_path / "excel.csv"
    if writer == "pandas":
        frame.to_csv(src, index=False, encoding="cp1252")
    else:
        src.write_bytes(frame.to_csv(index=False, lineterminator="\r\n").encode("cp1252"))
    assert b"\xb2" in src.read_bytes().splitlines()[0]
    stderr = _same_as_utf8(tmp_path, frame, src)
    lines = stderr.splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith(f"station: {src}: warning: "), stderr
    assert "byte 0xb2 on line 1" in lines[0] and "Windows-1252" in lines[0], stderr


def test_a_byte_windows_1252_does_not_define_is_still_refused(tmp_path, frame):
    """0x81 is no Windows-1252 character: such a file is neither encoding, refused as before,
    naming the first byte that is not UTF-8."""
    src = tmp_path / "excel.csv"
    frame.to_csv(src, index=False, encoding="cp1252")
    ok = _same_as_utf8(tmp_path, frame, src)  # the file without the stray byte is read
    assert "Windows-1252" in ok
    raw = src.read_bytes().splitlines(keepends=True)
    raw[3] = raw[3].replace(b",", b"\x81,", 1)  # a byte no Windows-1252 character is, on line 4
    stray = tmp_path / "stray.csv"
    stray.write_bytes(b"".join(raw))
    res, out = _import(tmp_path, stray)
    assert_one_line_refusal(res, f"{stray}:1: not UTF-8 text: byte 0xb2")
    assert not out.exists()
    marked = tmp_path / "marked.csv"  # a UTF-8 byte-order mark says UTF-8: a 0xb2 then is an error
    marked.write_bytes(codecs.BOM_UTF8 + src.read_bytes())
    res, out = _import(tmp_path, marked)
    assert_one_line_refusal(res, f"{marked}:1: not UTF-8 text: byte 0xb2")
    assert not out.exists()


@pytest.mark.parametrize("writer", ["pandas-utf-16-tab", "utf-16", "utf-16-be-with-bom"])
def test_utf16_with_a_byte_order_mark_is_read(tmp_path, frame, writer):
    """Excel's "Unicode Text" (UTF-16 LE with its mark, tab-separated) and UTF-16 BE with its
    mark: were refused as 'UTF-16 text'. Now read as UTF-16, without a word (nothing to warn:
    the mark says the encoding; the file's last line end is seen, so no 'cut short')."""
    src = tmp_path / "unicode.txt"
    sep = "\t" if writer.endswith("tab") else ","
    if writer == "pandas-utf-16-tab":
        frame.to_csv(src, index=False, encoding="utf-16", sep="\t")
    elif writer == "utf-16":
        src.write_bytes(frame.to_csv(index=False).encode("utf-16"))
    else:
        src.write_bytes(codecs.BOM_UTF16_BE + frame.to_csv(index=False).encode("utf-16-be"))
    assert src.read_bytes()[:2] in (codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)
    stderr = _same_as_utf8(tmp_path, frame, src, sep=sep)
    assert stderr == ""


def test_binary_data_behind_a_utf16_mark_is_refused_in_one_line(tmp_path):
    """A UTF-16 mark does not make a binary file text: a NUL character is refused on its line,
    as a NUL byte is (was: 'UTF-16 text; CSV files are read as UTF-8')."""
    src = tmp_path / "blob.csv"
    src.write_bytes("t,ax,ay,az\n0,1,2,3\n".encode("utf-16") + bytes(64) + "\n".encode("utf-16-le"))
    res, out = _import(tmp_path, src)
    assert_one_line_refusal(res, f"{src}:3: NUL character: binary data, not a CSV file")
    assert not out.exists()
