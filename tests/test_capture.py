"""Capture files: every kind of bad input named by file and line, exact round trips, real data.

Bad input is checked twice: through ``read_capture`` (the exact ``file:line: message``) and
through the real CLI in a subprocess (exit 2, one line on stderr, no traceback). Errors are
also checked with tiny read blocks, so a rule broken across a block boundary names the same
line as in one block.
"""

from __future__ import annotations

import csv
import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from station.capture import Capture, iter_capture_chunks, read_capture, write_capture
from station.errors import InputError
from station.procedures.registry import names as procedure_names

ROOT = Path(__file__).resolve().parents[1]
PY = ROOT / ".venv" / "bin" / "python"
PYTHON = str(PY) if PY.exists() else sys.executable

HEAD = "# station-capture: 1\n# procedure: accel-tabletop\n# device: D1\n# accel_unit: V\n"
HDR = "t,position,ax,ay,az\n"  # line 5 when HEAD precedes it
ROWS = "0.0,1,2.5,1.6,1.7\n0.5,1,2.5,1.6,1.7\n1.0,2,2.4,1.5,1.6\n"  # lines 6-8


def _good(extra: str = "") -> str:
    return HEAD + HDR + ROWS + extra


WAY_IN = "; for a log or another CSV use `station import FILE --procedure P --out CAPTURE` (README: Import)"
# (id, file content (str or bytes), line, message)
BAD = [
    ("empty", b"", 1, "empty file"),
    ("only-blank", b"\n\n  \n", 1, "empty file"),
    (
        "no-version-line",
        "t,ax\n0,1\n",
        1,
        "missing first line '# station-capture: 1': not a station capture file" + WAY_IN,
    ),
    (
        "version-not-first",
        "# procedure: ldv\n# station-capture: 1\nt,ax\n0,1\n",
        1,
        "missing first line '# station-capture: 1': not a station capture file" + WAY_IN,
    ),
    (
        "version-2",
        "# station-capture: 2\nt,ax\n0,1\n",
        1,
        "unsupported capture version '2' (this station reads version 1)",
    ),
    (
        "meta-without-colon",
        HEAD + "# recorded on the bench\n" + HDR + ROWS,
        5,
        "metadata line without 'key: value': '# recorded on the bench'",
    ),
    ("meta-empty-key", HEAD + "# : 3\n" + HDR + ROWS, 5, "metadata line without 'key: value': '# : 3'"),
    ("meta-duplicate", HEAD + "# device: D2\n" + HDR + ROWS, 5, "duplicate metadata key 'device' (first on line 3)"),
    ("no-header", HEAD, 5, "no header row (a line of column names must follow the metadata)"),
    ("header-is-numbers", HEAD + ROWS, 5, "no header row: this line holds numbers where the column names should be"),
    ("header-only", HEAD + HDR, 6, "no data rows after the header"),
    ("header-only-trailing-blanks", HEAD + HDR + "\n\n", 6, "no data rows after the header"),
    ("duplicate-column", HEAD + "t,ax,ay,ax\n0,1,2,3\n", 5, "duplicate column 'ax' (columns 2 and 4)"),
    ("empty-column-name", HEAD + "t,,ay\n0,1,2\n", 5, "empty column name (column 2 of the header)"),
    # every line ending in a comma is read (tests below); a value in that unnamed column is not
    (
        "trailing-comma-value",
        HEAD + "t,ax,\n0,1,\n1,2,7\n",
        7,
        "a value after the last column (column 3 has no name in the header)",
    ),
    ("empty-column-name-last-of-many", HEAD + "t,ax,,\n0,1,,\n", 5, "empty column name (column 3 of the header)"),
    (
        "quoted-column-name",  # a quote inside the name; CSV's quotes around it are read (test_foreign_writers)
        HEAD + 't,a"x\n0,1\n',
        5,
        "column name 'a\"x' is not plain text (no quotes or control characters)",
    ),
    (
        "unknown-procedure",
        "# station-capture: 1\n# procedure: accel-flat\nt,ax\n0,1\n",
        2,
        "unknown procedure 'accel-flat' (expected one of " + ", ".join(procedure_names()) + ")",
    ),
    (
        "unknown-accel-unit",
        "# station-capture: 1\n# device: x\n# accel_unit: furlongs\nt,ax\n0,1\n",
        3,
        "unknown accel_unit 'furlongs' (expected one of V, mV, counts, g, m/s^2, mps2, mg)",
    ),
    (
        "accel-unit-of-wrong-kind",
        "# station-capture: 1\n# accel_unit: deg/s\nt,ax\n0,1\n",
        2,
        "accel_unit 'deg/s' is not an acceleration unit (expected one of V, mV, counts, g, m/s^2, mps2, mg)",
    ),
    (
        "unknown-mag-unit",
        "# station-capture: 1\n# mag_unit: tesla\nt,mx\n0,1\n",
        2,
        "unknown mag_unit 'tesla' (expected one of V, mV, counts, nT, uT, gauss, G, mG, mgauss)",
    ),
    ("meta-not-a-number", HEAD + "# g_mps2: 9,81\n" + HDR + ROWS, 5, "metadata 'g_mps2': '9,81' is not a number"),
    ("meta-nan", HEAD + "# radius_m: nan\n" + HDR + ROWS, 5, "metadata 'radius_m': 'nan' is not a number"),
    (
        "latitude-out-of-range",
        HEAD + "# latitude_deg: 95\n" + HDR + ROWS,
        5,
        "metadata 'latitude_deg': '95' must be between -90 and 90",
    ),
    (
        "bad-date",
        HEAD + "# date: 21/11/2026\n" + HDR + ROWS,
        5,
        "metadata 'date': '21/11/2026' is not an ISO date (YYYY-MM-DD[THH:MM:SS])",
    ),
    (
        "bad-gyro-mode",
        HEAD + "# gyro_mode: spinning\n" + HDR + ROWS,
        5,
        "unknown gyro_mode 'spinning' (expected one of reference, static)",
    ),
    ("not-a-number", _good("1.5,2,2.4,abc,1.6\n"), 9, "column 'ay': 'abc' is not a number"),
    (
        "decimal-comma",
        HEAD + "t;ax\n0;1,5\n",
        5,
        "the header's columns are separated by ';' (semicolons): a capture's are separated by commas, "
        "with '.' as the decimal mark",
    ),
    (
        "literal-nan",
        _good("1.5,2,nan,1.5,1.6\n"),
        9,
        "column 'ax': 'nan' is not allowed: leave the field empty for a missing value",
    ),
    (
        "literal-NaN-t",
        _good("NaN,2,2.4,1.5,1.6\n"),
        9,
        "column 't': 'NaN' is not allowed: leave the field empty for a missing value",
    ),
    (
        "literal-inf",
        _good("1.5,2,2.4,-inf,1.6\n"),
        9,
        "column 'ay': '-inf' is not allowed: leave the field empty for a missing value",
    ),
    ("overflow", _good("1.5,2,2.4,1e999,1.6\n"), 9, "column 'ay': '1e999' is out of range"),
    ("underscore-digits", _good("1.5,2,2_400,1.5,1.6\n"), 9, "column 'ax': '2_400' is not a number"),
    ("unicode-digits", _good("1.5,2,\u0662,1.5,1.6\n"), 9, "column 'ax': '\u0662' is not a number"),
    ("too-many-fields", _good("1.5,2,2.4,1.5,1.6,9\n"), 9, "too many fields: 6 where the header has 5 columns"),
    ("too-few-fields", _good("1.5,2,2.4,1.5\n"), 9, "too few fields: 4 where the header has 5 columns"),
    (
        "t-backwards",
        HEAD + HDR + "1.0,1,2.5,1.6,1.7\n2.0,1,2.5,1.6,1.7\n1.5,1,2.5,1.6,1.7\n",
        8,
        "t goes backwards: 1.5 after 2.0",
    ),
    ("t-empty", _good(",2,2.4,1.5,1.6\n"), 9, "column 't': empty (every row of a time series needs its time)"),
    (
        "comment-in-data",
        _good("# a note\n1.5,2,2.4,1.5,1.6\n"),
        9,
        "comment line inside the data (# lines must come before the header)",
    ),
    (
        "comment-in-data-text-first",
        HEAD + "position,ax\n1,2.5\n#2,2.5\n",
        7,
        "comment line inside the data (# lines must come before the header)",
    ),
    (
        "blank-line-in-data",
        _good("\n1.5,2,2.4,1.5,1.6\n"),
        9,
        "blank line inside the data (only trailing blank lines are allowed)",
    ),
    (
        "nul-byte-data",
        _good().encode() + b"1.5,2,2.4\x00,1.5,1.6\n",
        9,
        "NUL byte at column 10: binary data, not a text capture",
    ),
    (
        "nul-byte-first-line",
        b"\x00\x01\x02binary\n\xff\xfe",
        1,
        "NUL byte at column 1: binary data, not a text capture",
    ),
    # not UTF-8 and not Windows-1252 either (0x81 is no character of it; 0xff, 0xe9 are: qa-s27i reads them)
    (
        "bad-utf8-data",
        _good().encode() + b"1.5,\x812,2.4,1.5,1.6\n",
        9,
        "not UTF-8 text: byte 0x81 (nor a Windows-1252 character): save the file as UTF-8",
    ),
    (
        "bad-utf8-meta",
        b"# station-capture: 1\n# device: caf\x81\n" + (HDR + ROWS).encode(),
        2,
        "not UTF-8 text: byte 0x81 (nor a Windows-1252 character): save the file as UTF-8",
    ),
    ("png", b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR", 3, "NUL byte: binary data, not a capture file"),
    (
        "utf16-without-mark",
        "# station-capture: 1\nt,ax\n0,1\n".encode("utf-16-le"),
        1,
        "UTF-16 text without a byte-order mark; save the file as UTF-8 (or as Unicode Text, with one)",
    ),
    (
        "bare-cr-endings",
        b"# station-capture: 1\rt,ax\r0,1\r",
        1,
        "stray carriage return (\\r) inside the line; use LF or CRLF line endings",
    ),
    (  # a whole capture on one 'line' (over 1 MiB): was 'line longer than 1048576 bytes: not a capture file'
        "bare-cr-endings-long",
        b"# station-capture: 1\r# procedure: accel-tabletop\rt,ax\r" + b"0.000,1.000\r" * 100000,
        1,
        "carriage returns (\\r) end the lines; use LF or CRLF line endings",
    ),
    (
        "quote-in-label",  # inside the label; CSV's quotes around it are read (test_foreign_writers)
        _good('1.5,x"p,2.4,1.5,1.6\n'),
        9,
        "column 'position': 'x\"p' holds a quote, which plain CSV cannot hold",
    ),
    ("tab-in-label", _good("1.5,x\tp,2.4,1.5,1.6\n"), 9, "column 'position': 'x\\tp' holds a control character"),
    (
        "n-not-whole",
        HEAD + "position,n,ax,ax_std\n1,10,2.5,0.01\n2,2.5,2.5,0.01\n",
        7,
        "column 'n': '2.5' is not a whole number of samples (1 or more)",
    ),
    (
        "std-negative",
        HEAD + "position,n,ax,ax_std\n1,10,2.5,0.01\n2,10,2.5,-0.01\n",
        7,
        "column 'ax_std': '-0.01' is negative (it is a standard deviation)",
    ),
]


def _write(tmp_path: Path, content, name: str = "bad.capture.csv") -> Path:
    path = tmp_path / name
    path.write_bytes(content if isinstance(content, bytes) else content.encode("utf-8"))
    return path


@pytest.mark.parametrize("rows", [65536, 1], ids=["one-block", "row-blocks"])
@pytest.mark.parametrize("content,line,message", [b[1:] for b in BAD], ids=[b[0] for b in BAD])
def test_bad_input_names_file_line_and_problem(tmp_path, content, line, message, rows):
    path = _write(tmp_path, content)
    with pytest.raises(InputError) as err:
        read_capture(path, rows=rows)
    assert (err.value.path, err.value.line, err.value.message) == (str(path), line, message)
    assert str(err.value) == f"{path}:{line}: {message}"


@pytest.mark.parametrize("content,line,message", [b[1:] for b in BAD], ids=[b[0] for b in BAD])
def test_bad_input_through_the_cli(tmp_path, content, line, message):
    path = _write(tmp_path, content)
    out = subprocess.run(
        [PYTHON, "-m", "station", "inspect", str(path)], cwd=ROOT, capture_output=True, text=True, timeout=60
    )
    assert out.returncode == 2
    assert out.stdout == ""
    assert "Traceback" not in out.stderr
    assert out.stderr.endswith("\n") and out.stderr.count("\n") == 1, out.stderr
    assert f"{path}:{line}: {message}" in out.stderr


def test_missing_file_and_directory(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        read_capture(tmp_path / "absent.csv")
    with pytest.raises(InputError, match="is a directory"):
        read_capture(tmp_path)


def test_error_deep_in_a_large_file_names_its_line(tmp_path):
    # 20,000 good rows, then a bad one: many blocks parse on the fast path first.
    t = np.arange(20_000) * 0.01
    body = "\n".join(f"{x:.2f},1,{x:.3f}" for x in t)
    path = _write(tmp_path, HEAD + "t,position,ax\n" + body + "\n200.5,1,1.2.3\n")
    with pytest.raises(InputError) as err:
        read_capture(path, rows=1000)
    assert err.value.line == 5 + 20_000 + 1
    assert err.value.message == "column 'ax': '1.2.3' is not a number"


def test_t_backwards_across_a_block_boundary_quotes_the_file_text(tmp_path):
    path = _write(tmp_path, HEAD + "t,ax\n0.10,1\n0.20,1\n0.30,1\n0.25,1\n")
    for rows in (1, 2, 3, 100):
        with pytest.raises(InputError) as err:
            read_capture(path, rows=rows)
        assert (err.value.line, err.value.message) == (9, "t goes backwards: 0.25 after 0.30")


# ----------------------------------------------------------------------- what is accepted


def test_good_capture_reads_exactly(tmp_path):
    path = _write(tmp_path, HEAD + "# lab note: bench 3: left\n" + HDR + ROWS)
    c = read_capture(path)
    assert list(c.meta.items()) == [
        ("station-capture", "1"),
        ("procedure", "accel-tabletop"),
        ("device", "D1"),
        ("accel_unit", "V"),
        ("lab note", "bench 3: left"),
    ]
    assert list(c.columns) == ["t", "position", "ax", "ay", "az"]
    assert c.columns["t"].dtype == np.float64 and c.columns["t"].tolist() == [0.0, 0.5, 1.0]
    assert c.columns["position"].dtype == object and c.columns["position"].tolist() == ["1", "1", "2"]
    assert c.columns["ax"].tolist() == [2.5, 2.5, 2.4]
    assert c.procedure == "accel-tabletop" and c.is_time_series and c.n_rows == 3 and c.path == str(path)
    assert c.meta_lines["lab note"] == 5 and c.header_line == 6


def test_crlf_bom_trailing_blanks_whitespace_and_missing_values(tmp_path):
    text = (
        "\ufeff# station-capture: 1\r\n#device :  D 7 \r\n\r\n t , position , ax \r\n"
        "0, x_p ,1.5\r\n1,, \r\n2,x_p,-3e2\r\n\r\n  \r\n"
    )
    c = read_capture(_write(tmp_path, text))
    assert c.meta == {"station-capture": "1", "device": "D 7"}
    assert list(c.columns) == ["t", "position", "ax"]
    assert c.columns["position"].tolist() == ["x_p", "", "x_p"]
    ax = c.columns["ax"]
    assert ax[0] == 1.5 and math.isnan(ax[1]) and ax[2] == -300.0
    assert c.procedure is None  # a missing procedure is fine for reading


def test_every_line_ending_in_a_comma_is_read(tmp_path):
    """A spreadsheet's or logger's export that ends every line, header included, with a comma:
    the unnamed empty column after it is not part of the capture; the fast path (blocks) and the
    per-cell path read it alike, CRLF and missing values included."""
    lines = [f"{i * 0.01!r},{'' if i % 7 == 3 else repr(0.5 * i)},{'x_p' if i < 60 else 'y_p'}," for i in range(120)]
    text = HEAD + "t,ax,position,\r\n" + "\r\n".join(lines) + "\r\n"
    path = _write(tmp_path, text)
    fast = read_capture(path, rows=16)
    slow = read_capture(path, _force_slow=True)
    assert fast == slow
    assert list(fast.columns) == ["t", "ax", "position"]
    assert np.isnan(fast.columns["ax"]).sum() == sum(i % 7 == 3 for i in range(120))
    assert fast.columns["position"].tolist()[58:62] == ["x_p", "x_p", "y_p", "y_p"]


def test_fast_and_per_cell_paths_agree_on_missing_values_and_labels(tmp_path):
    rng = np.random.default_rng(7)
    lines = []
    for i in range(3000):
        ax = "" if rng.random() < 0.05 else repr(float(rng.normal()))
        label = ["", "1", "x_p", "pos é", "z" * 40][int(rng.integers(5))]
        lines.append(f"{i * 0.01!r},{label},{ax},{rng.normal()!r}")
    path = _write(tmp_path, HEAD + "t,position,ax,ay\n" + "\n".join(lines) + "\n")
    fast = read_capture(path, rows=256)
    slow = read_capture(path, _force_slow=True)
    assert fast == slow
    assert fast.columns["position"].tolist() == [ln.split(",")[1] for ln in lines]
    assert np.isnan(fast.columns["ax"]).sum() == sum(ln.split(",")[2] == "" for ln in lines)


_CELL = st.text(alphabet="0123456789.+-eE _xnaifINF\t,", min_size=0, max_size=8)


@settings(max_examples=250, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(rows=st.lists(st.lists(_CELL, min_size=3, max_size=3), min_size=1, max_size=3))
def test_fast_path_accepts_exactly_what_the_per_cell_rules_accept(tmp_path, rows):
    body = "".join(f"{i},{','.join(cells)}\n" for i, cells in enumerate(rows))
    path = _write(tmp_path, "# station-capture: 1\nt,position,a,b\n" + body)

    def outcome(**kw):
        try:
            return read_capture(path, **kw)
        except InputError as exc:
            return str(exc)

    fast, slow = outcome(), outcome(_force_slow=True)
    assert fast == slow


def test_missing_values_stay_on_the_fast_path(tmp_path):
    from station.capture import _Parser

    rng = np.random.default_rng(3)
    lines = []
    for i in range(2000):
        label = "" if rng.random() < 0.3 else f"p{i // 100}"
        temp = "" if i % 10 else f"{25 + rng.normal():.3f}"  # a slow sensor: one value in ten rows
        ax = "" if rng.random() < 0.01 else f"{rng.normal():.6f}"
        lines.append(f"{i / 100:.2f},{label},{ax},{temp}")
    path = _write(tmp_path, HEAD + "t,position,ax,temp_c\n" + "\n".join(lines) + "\n")
    block = path.read_bytes().split(b"\n", 5)[5]
    assert _Parser(str(path), ["t", "position", "ax", "temp_c"])._fast(block, 2000) is not None
    c = read_capture(path)
    assert c == read_capture(path, _force_slow=True)
    assert np.isnan(c.columns["temp_c"]).sum() == 1800
    assert c.columns["position"].tolist() == [ln.split(",")[1] for ln in lines]


def test_float_meta_and_column_helpers(tmp_path):
    path = _write(tmp_path, HEAD + "# g_mps2: 9.80665\n# note: 12 apples\n" + HDR + ROWS)
    c = read_capture(path)
    assert c.float_meta("g_mps2") == 9.80665
    assert c.float_meta("radius_m") is None and c.float_meta("radius_m", 1.5) == 1.5
    with pytest.raises(InputError) as err:
        c.float_meta("note")
    assert str(err.value) == f"{path}:6: metadata 'note': '12 apples' is not a number"
    with pytest.raises(InputError) as err:
        c.column("mx")
    assert str(err.value) == f"{path}:7: no column 'mx' (columns: t, position, ax, ay, az)"
    assert c.unit("ax") == "V" and c.unit("t") == "s" and c.unit("gx") is None


def test_iter_capture_chunks_streams_the_same_data(tmp_path):
    t = np.arange(10_000) * 0.01
    path = _write(tmp_path, HEAD + "t,ax\n" + "".join(f"{x!r},{x * 2!r}\n" for x in t.tolist()))
    meta, header, chunks = iter_capture_chunks(path, rows=1000)
    assert meta["device"] == "D1" and header == ["t", "ax"]
    parts = list(chunks)
    assert len(parts) >= 5 and all(len(p["t"]) <= 1100 for p in parts)
    assert np.array_equal(np.concatenate([p["t"] for p in parts]), t)
    assert np.array_equal(np.concatenate([p["ax"] for p in parts]), t * 2)


def test_iter_capture_chunks_checks_the_head_at_once(tmp_path):
    with pytest.raises(InputError, match="unsupported capture version"):
        iter_capture_chunks(_write(tmp_path, "# station-capture: 9\nt\n1\n"))


# ---------------------------------------------------------------------------- round trips

_FLOATS = st.floats(allow_nan=True, allow_infinity=False)  # subnormals, ±1.8e308, -0.0, NaN
_FINITE = st.floats(allow_nan=False, allow_infinity=False)  # no empty fields: the numpy fast path reads these
_ASCII_LABEL = st.text(alphabet="abcxyz_+-019 ", max_size=8).map(str.strip)
_LABEL = st.text(
    alphabet=st.characters(blacklist_categories=("Cc", "Cf", "Cs", "Co", "Cn", "Zl", "Zp"), blacklist_characters=',"'),
    max_size=12,
).filter(lambda s: s == s.strip() and s.isprintable())


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data(), n=st.integers(min_value=1, max_value=40))
def test_write_then_read_gives_back_the_same_capture(tmp_path, data, n):
    t = np.sort(np.array(data.draw(st.lists(st.floats(-1e12, 1e12), min_size=n, max_size=n))))
    cols = {
        "t": t,
        "position": np.array(
            data.draw(st.lists(st.one_of(_LABEL, _ASCII_LABEL), min_size=n, max_size=n)), dtype=object
        ),
        "ax": np.array(data.draw(st.lists(data.draw(st.sampled_from([_FLOATS, _FINITE])), min_size=n, max_size=n))),
        "temp_c": np.array(data.draw(st.lists(st.floats(-1e-300, 1e-300), min_size=n, max_size=n))),
    }
    meta = {
        "station-capture": "1",
        "procedure": "gyro-drift",
        "device": data.draw(_LABEL),
        "free-form": data.draw(st.text(alphabet="abc :#,=é", max_size=10).map(str.strip)),
    }
    c = Capture(meta=meta, columns=cols)
    path = tmp_path / "rt.capture.csv"
    write_capture(path, c)
    back = read_capture(path)
    assert back == c
    assert read_capture(path, _force_slow=True) == c
    for name in ("t", "ax", "temp_c"):  # bit for bit, NaN where NaN
        a, b = cols[name], back.columns[name]
        nan = np.isnan(a)
        assert np.array_equal(nan, np.isnan(b))
        assert np.array_equal(a[~nan].view(np.int64), b[~nan].view(np.int64))


def test_round_trip_of_extreme_and_integer_values(tmp_path):
    x = np.array(
        [
            0.0,
            -0.0,
            5e-324,
            -2.2250738585072014e-308,
            1.7976931348623157e308,
            33108.0,
            1e16,
            0.1,
            1 / 3,
            np.nan,
            -123456789012345.0,
        ]
    )
    c = Capture({"station-capture": "1"}, {"ax": x, "n": np.arange(1.0, len(x) + 1)})
    path = tmp_path / "x.capture.csv"
    write_capture(path, c)
    assert read_capture(path) == c
    text = path.read_text().splitlines()
    assert text[:2] == ["# station-capture: 1", "ax,n"]
    assert text[2 + 5].startswith("33108,") and text[2 + 9] == ",10"  # ints without '.0', NaN empty
    back = read_capture(path).columns["ax"]
    assert np.signbit(back[1]) and back[2] == 5e-324


def test_fast_path_reads_extreme_values_bit_for_bit(tmp_path):
    from station.capture import _Parser

    x = np.array(
        [
            0.0,
            -0.0,
            5e-324,
            2.2250738585072014e-308,
            -1.7976931348623157e308,
            0.1,
            1 / 3,
            33108.0,
            -9007199254740993.0,
            1e22,
            123.456e-7,
        ]
    )
    c = Capture(
        {"station-capture": "1"},
        {"t": np.arange(len(x), dtype=float), "position": np.array(["a"] * 5 + ["b"] * 6, dtype=object), "ax": x},
    )
    path = tmp_path / "x.capture.csv"
    write_capture(path, c)
    block = path.read_bytes().split(b"\n", 2)[2]
    assert _Parser(str(path), ["t", "position", "ax"])._fast(block, len(x)) is not None  # no fallback
    back = read_capture(path)
    assert back == c and back == read_capture(path, _force_slow=True)
    assert np.array_equal(back.columns["ax"].view(np.int64), x.view(np.int64))


def test_real_capture_round_trips(shared_data, tmp_path):
    c = read_capture(shared_data / "imucal_ferraris" / "imucal_ferraris_labelled.capture.csv")
    write_capture(tmp_path / "copy.capture.csv", c)
    assert read_capture(tmp_path / "copy.capture.csv") == c


@pytest.mark.parametrize(
    "label,shown,why",
    [
        ("a,b", "'a,b'", "holds a comma, which plain CSV cannot hold"),
        ('say "x"', "'say \"x\"'", "holds a quote or a control character, which plain CSV cannot hold"),
        ("two\nlines", "'two\\nlines'", "holds a quote or a control character, which plain CSV cannot hold"),
        (" x_p", "' x_p'", "has spaces at the ends, which the reader would strip"),
    ],
)
def test_writer_refuses_labels_plain_csv_cannot_hold(tmp_path, label, shown, why):
    path = tmp_path / "w.capture.csv"
    c = Capture({"station-capture": "1"}, {"t": np.array([0.0, 1.0]), "position": np.array(["1", label], dtype=object)})
    with pytest.raises(InputError) as err:
        write_capture(path, c)
    assert str(err.value) == f"{path}: column 'position', row 2: label {shown} {why}"
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize(
    "cols,meta,fragment",
    [
        ({"t": [0.0, np.inf]}, {}, "column 't', row 2: inf cannot be written"),
        ({"t": [0.0, np.nan]}, {}, "column 't', row 2: nan cannot be written"),
        ({"t": [1.0, 0.5]}, {}, "column 't', row 2: t goes backwards: 0.5 after 1.0"),
        ({"ax": [1.0, -np.inf]}, {}, "column 'ax', row 2: -inf cannot be written"),
        ({"n": [3.0, 0.0]}, {}, "column 'n', row 2: 0.0 is not a whole number of samples"),
        ({"ax": [1.0, np.nan]}, {}, "a one-column capture cannot hold a missing value"),
        ({"t": [0.0], "t ": [1.0]}, {}, "column name 't ' cannot be written"),
        ({"#t": [0.0]}, {}, "would read as a comment"),
        ({"position": ["#1"], "ax": [1.0]}, {}, "starts with '#' in the first column"),
        ({"ax": [1.0]}, {"procedure": "accel-flat"}, "unknown procedure 'accel-flat'"),
        ({"ax": [1.0]}, {"device": "a\nb"}, "cannot be written"),
        ({"ax": [1.0]}, {"a:b": "c"}, "cannot be written"),
        ({"ax": [1.0]}, {"station-capture": "2"}, "unsupported capture version '2'"),
        ({"ax": [], "ay": []}, {}, "capture has no data rows"),
        ({"ax": [1.0], "ay": [1.0, 2.0]}, {}, "columns differ in length (ax=1, ay=2)"),
    ],
)
def test_writer_refuses_what_the_reader_would_refuse(tmp_path, cols, meta, fragment):
    path = tmp_path / "w.capture.csv"
    columns = {k: np.array(v, dtype=object if k == "position" else float) for k, v in cols.items()}
    with pytest.raises(InputError) as err:
        write_capture(path, Capture({"station-capture": "1", **meta}, columns))
    assert fragment in err.value.message
    assert os.listdir(tmp_path) == []


# ------------------------------------------------------------------------------ atomicity


def _big_capture(n: int) -> Capture:
    t = np.arange(n) * 0.01
    pos = np.array([str(i // 1000) for i in range(n)], dtype=object)
    return Capture({"station-capture": "1", "procedure": "accel-tabletop"}, {"t": t, "position": pos, "ax": t * 3})


def test_refusal_mid_write_leaves_the_old_file_and_no_temp(tmp_path):
    path = tmp_path / "c.capture.csv"
    path.write_text("old content\n")
    c = _big_capture(20_000)
    c.columns["position"][15_000] = "1,5"  # found only when the writer reaches row 15,001
    with pytest.raises(InputError, match=r"row 15001: label '1,5' holds a comma"):
        write_capture(path, c, rows=1000)
    assert path.read_text() == "old content\n"
    assert sorted(os.listdir(tmp_path)) == ["c.capture.csv"]


class _Exploding(np.ndarray):
    """A column whose rows past 10,000 cannot be read: the writer dies half-way."""

    def __getitem__(self, item):
        if isinstance(item, slice) and (item.start or 0) >= 10_000:
            raise RuntimeError("disk on fire")
        return super().__getitem__(item)


def test_exception_mid_write_leaves_no_partial_file(tmp_path):
    path = tmp_path / "c.capture.csv"
    c = _big_capture(20_000)
    c.columns["ax"] = c.columns["ax"].view(_Exploding)
    with pytest.raises(RuntimeError, match="disk on fire"):
        write_capture(path, c, rows=1000)
    assert os.listdir(tmp_path) == []
    write_capture(path, _big_capture(20_000), rows=1000)  # the same path works afterwards
    assert read_capture(path).n_rows == 20_000


def test_write_to_a_missing_folder_or_onto_a_directory(tmp_path):
    c = _big_capture(10)
    with pytest.raises(InputError, match="cannot write: no folder .*nope"):
        write_capture(tmp_path / "nope" / "c.capture.csv", c)
    (tmp_path / "d").mkdir()
    with pytest.raises(InputError, match="cannot write: is a folder"):
        write_capture(tmp_path / "d", c)
    assert os.listdir(tmp_path) == ["d"] and os.listdir(tmp_path / "d") == []


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0, reason="root ignores folder permissions")
def test_write_into_a_read_only_folder(tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o555)
    try:
        with pytest.raises(InputError, match="cannot write: Permission denied"):
            write_capture(folder / "c.capture.csv", _big_capture(10))
        assert os.listdir(folder) == []
    finally:
        folder.chmod(0o755)


def test_written_file_keeps_the_old_mode(tmp_path):
    path = tmp_path / "c.capture.csv"
    write_capture(path, _big_capture(5))
    ordinary = tmp_path / "ordinary"
    ordinary.write_text("")  # what open() makes under this umask (0o644 under 022)
    assert (path.stat().st_mode & 0o777) == (ordinary.stat().st_mode & 0o777)
    path.chmod(0o640)
    write_capture(path, _big_capture(6))
    assert (path.stat().st_mode & 0o777) == 0o640 and read_capture(path).n_rows == 6


# ------------------------------------------------------------------------------ real data


def _readme_rows(shared_data: Path) -> dict[str, tuple[int, float]]:
    """capture name -> (rows, duration_s) from the table in ../shared/data/README.md."""
    text = (shared_data / "README.md").read_text()
    rows = {}
    for m in re.finditer(r"`([\w.]+\.capture\.csv)`[^\n]*?\|\s*([\d,]+), ([\d.]+) s\s*\|", text):
        rows[m.group(1)] = (int(m.group(2).replace(",", "")), float(m.group(3)))
    return rows


def test_readme_table_is_parsed(shared_data):
    assert len(_readme_rows(shared_data)) == 12


def test_every_shared_capture_reads_with_the_documented_rows(shared_data):
    documented = _readme_rows(shared_data)
    files = sorted(shared_data.glob("*/*.capture.csv"))
    assert len(files) == 13
    for path in files:
        c = read_capture(path)
        assert c.meta["station-capture"] == "1" and c.procedure in procedure_names(), path
        if path.name == "table1.capture.csv":
            continue
        rows, duration_s = documented[path.name]
        assert c.n_rows == rows, path
        assert c.is_time_series
        # README rounds the duration to 0.1 s
        assert abs((c.columns["t"][-1] - c.columns["t"][0]) - duration_s) <= 0.05 + 1e-9, path


def test_table_of_averages_reads_with_sixty_rows(shared_data):
    c = read_capture(shared_data / "wang2021_centrifuge" / "table1.capture.csv")
    assert c.n_rows == 60 and not c.is_time_series  # SOURCE.md: 20 positions x 3 speeds
    assert list(c.columns) == ["position", "speed_rad_s", "ax", "ay", "az"]
    assert c.columns["position"].tolist()[:3] == ["1", "2", "3"]
    assert sorted(set(np.round(c.columns["speed_rad_s"] / np.pi, 12))) == [2.0, 4.0, 6.0]
    assert c.float_meta("radius_m") == 1.0 and c.float_meta("g_mps2") == 9.8


@pytest.mark.parametrize(
    "name",
    [
        "imucal_ferraris/imucal_ferraris_labelled.capture.csv",
        "sunsided_marg/sunsided_full_sphere.capture.csv",
        "wang2021_centrifuge/table1.capture.csv",
    ],
)
def test_shared_capture_values_match_an_independent_csv_parse(shared_data, name):
    path = shared_data / name
    with open(path, newline="") as f:
        lines = [ln for ln in f.read().splitlines()]
    n_meta = next(i for i, ln in enumerate(lines) if not ln.startswith("#"))
    rows = list(csv.reader(lines[n_meta + 1 :]))
    header = lines[n_meta].split(",")
    c = read_capture(path)
    fast_vs_slow = read_capture(path, _force_slow=True)
    assert c == fast_vs_slow
    for j, name in enumerate(header):
        want = [r[j] for r in rows]
        if name == "position":
            assert c.columns[name].tolist() == want
        else:
            expected = np.array([float(v) if v else np.nan for v in want])
            assert np.array_equal(c.columns[name], expected, equal_nan=True)


# ------------------------------------------------------------------------------ the command


def _station(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([PYTHON, "-m", "station", *args], cwd=ROOT, capture_output=True, text=True, timeout=60)


def test_inspect_prints_a_summary(shared_data):
    path = shared_data / "imu_tk_xsens" / "imu_tk_xsens.capture.csv"
    out = _station("inspect", str(path))
    assert out.returncode == 0, out.stderr
    text = out.stdout
    assert "procedure:  accel-tabletop" in text and "device:     xsens-mti-imu_tk" in text
    assert "rows:       51175" in text
    duration = re.search(r"duration:\s+([\d.]+) s", text)
    assert duration and abs(float(duration.group(1)) - 511.7) <= 0.05  # README: 511.7 s
    rate = re.search(r"rate:\s+([\d.]+) Hz", text)
    assert rate and abs(float(rate.group(1)) - (51175 - 1) / 511.688) < 1e-3  # README: 100 Hz logger
    assert re.search(r"^  ax\s+counts\s+min", text, re.M)
    assert "  g_mps2: 9.81744" in text


def test_inspect_json(shared_data, tmp_path):
    out = _station("inspect", str(shared_data / "wang2021_centrifuge" / "table1.capture.csv"), "--json")
    assert out.returncode == 0, out.stderr
    s = json.loads(out.stdout)
    assert s["rows"] == 60 and s["kind"] == "table of averages" and s["positions"] == 20
    assert s["procedure"] == "accel-centrifuge" and s["duration_s"] is None
    assert [c["name"] for c in s["columns"]] == ["position", "speed_rad_s", "ax", "ay", "az"]
    assert {c["name"]: c["unit"] for c in s["columns"]}["ax"] == "g"
    assert s["metadata"]["radius_m"] == "1"
    # sunsided's t is i / sample_rate_hz rounded to 10 µs: the record's rate gives that rate back
    out = _station("inspect", str(shared_data / "sunsided_marg" / "sunsided_unmoved_x_forward.capture.csv"), "--json")
    s = json.loads(out.stdout)
    assert abs(s["rate_hz"] - s["sample_rate_hz"]) < 1e-3 and s["sample_rate_hz"] == 99.3738
    assert s["median_step_s"] == pytest.approx(0.01006, abs=1e-9)


def test_inspect_missing_file_is_one_line(tmp_path):
    out = _station("inspect", str(tmp_path / "nope.csv"))
    assert out.returncode == 2 and out.stderr.count("\n") == 1 and "no such file" in out.stderr


def test_export_capture_gives_back_the_stored_capture(shared_data, tmp_path):
    from db.store import Store

    original = read_capture(shared_data / "imucal_ferraris" / "imucal_ferraris_labelled.capture.csv")
    db = tmp_path / "station.db"
    store = Store(str(db))
    try:
        capture_id = store.save_capture(
            device_id="imucal-example-sensor",
            procedure=original.procedure,
            meta=original.meta,
            columns=original.columns,
        )
    finally:
        store.close()
    out = tmp_path / "exported.capture.csv"
    done = _station("export-capture", str(capture_id), "-o", str(out), "--db", str(db))
    assert done.returncode == 0, done.stderr
    assert read_capture(out) == original
    to_stdout = _station("export-capture", str(capture_id), "--db", str(db))
    assert to_stdout.returncode == 0 and to_stdout.stdout == out.read_text()
    missing = _station("export-capture", str(capture_id + 1), "--db", str(db))
    assert missing.returncode == 2 and missing.stderr.count("\n") == 1 and "Traceback" not in missing.stderr
    assert f"no capture {capture_id + 1}" in missing.stderr


def _with_rate(src, dst, rate: str):
    """``src`` with its sample_rate_hz line stated as ``rate``; the line number it sits on."""
    lines = src.read_text(encoding="utf-8").splitlines(keepends=True)
    at = next(i for i, line in enumerate(lines) if line.startswith("# sample_rate_hz:"))
    lines[at] = f"# sample_rate_hz: {rate}\n"
    dst.write_text("".join(lines), encoding="utf-8")
    return at + 1


def test_inspect_refuses_a_compass_rate_that_t_contradicts(shared_data, tmp_path):
    # the real sunsided record logged at 99.05 Hz, stated as 50 Hz: calibrate refuses it, so must inspect
    path = tmp_path / "sphere.capture.csv"
    line = _with_rate(shared_data / "sunsided_marg" / "sunsided_full_sphere.capture.csv", path, "50")
    out = _station("inspect", str(path))
    assert out.returncode == 2 and out.stdout == "" and out.stderr.count("\n") == 1, out.stderr
    assert f"{path}:{line}:" in out.stderr and "sample_rate_hz" in out.stderr and "t column" in out.stderr
    calibrated = _station("calibrate", str(path))
    assert calibrated.returncode == 2 and f"{path}:{line}:" in calibrated.stderr


def test_inspect_warns_of_a_rate_that_t_contradicts(shared_data, tmp_path):
    # imucal's labelled session logged at 102.4 Hz, stated as 400 Hz: P1's labelled positions do
    # not use t (its gyro block does, and is left uncalibrated), noise does
    real = shared_data / "imucal_ferraris" / "imucal_ferraris_labelled.capture.csv"
    path = tmp_path / "ferraris.capture.csv"
    line = _with_rate(real, path, "400")
    out = _station("inspect", str(path), "--json")
    assert out.returncode == 0, out.stderr
    (warning,) = json.loads(out.stdout)["warnings"]
    assert warning.startswith(f"line {line}:") and "400 Hz" in warning and "station noise" in warning
    assert "gyro uncalibrated" in warning
    text = _station("inspect", str(path)).stdout
    assert re.search(rf"^warning:\s+line {line}: metadata 'sample_rate_hz': 400 Hz", text, re.M)
    plain = _station("inspect", str(real), "--json")
    assert json.loads(plain.stdout)["warnings"] == []


@pytest.mark.parametrize("command", ["inspect", "calibrate"])
def test_a_rate_that_t_contradicts_is_refused_where_p1_finds_its_positions_over_t(shared_data, tmp_path, command):
    # the real imu_tk record logged at 100 Hz, stated as 400 Hz, no position column: stillness
    # detection finds the positions over windows of t, so t or the rate is wrong where it matters
    path = tmp_path / "xsens.capture.csv"
    line = _with_rate(shared_data / "imu_tk_xsens" / "imu_tk_xsens.capture.csv", path, "400")
    out = _station(command, str(path))
    assert out.returncode == 2 and out.stdout == "" and out.stderr.count("\n") == 1, out.stderr
    assert f"{path}:{line}: metadata 'sample_rate_hz': 400 Hz" in out.stderr and "windows of t" in out.stderr
