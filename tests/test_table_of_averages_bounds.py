"""A table of averages whose ``n`` or ``<col>_std`` no hold can have (capture-format.md: per-position
means, ``n`` samples averaged, ``<col>_std`` their standard deviation). Before, ``n`` = 1e19 and
``ax_std`` = 1e15 V were read and weighed: every position's sigma (std / sqrt(n)) was 3e5 V, any
fit looked within noise and `calibrate --save` stored it as accepted. Now the reader refuses
``n`` above 1e9 and a standard deviation more than 1e3 times the largest mean of its quantity in
the table (in any unit), on its line (README: tables of averages). An outside tester's finding
(branch qa-s24d)."""

from __future__ import annotations

import sqlite3

import numpy as np
import pytest

from station.capture import Capture, iter_capture_chunks, read_capture, write_capture
from station.errors import InputError
from tests.station_run import assert_one_line_refusal, run_station

AXES = ("ax", "ay", "az")
# The simulated table is in V (offset 1.65 V, 0.33 V per g, roughly); the same table in the units a
# bench writes: value -> value in that unit (means), and the factor of its standard deviations.
UNITS = {
    "V": (lambda v: v, 1.0),
    "counts": (lambda v: np.round(v * 13107.0, 1), 13107.0),
    "g": (lambda v: (v - 1.65) / 0.33, 1 / 0.33),
    "m/s^2": (lambda v: (v - 1.65) / 0.33 * 9.80665, 9.80665 / 0.33),
}


@pytest.fixture(scope="module")
def table_v(tmp_path_factory):
    src = tmp_path_factory.mktemp("sim") / "p1.csv"
    res = run_station(
        "simulate", "--procedure", "accel-tabletop", "--out", src, "--seed", "5", "--option", "averages=1"
    )
    assert res.returncode == 0, res.stderr
    return src


def _table(table_v, tmp_path, unit: str = "V", edit=None):
    """The simulated P1 table in ``unit``, ``edit(columns)`` applied as text the writer would refuse:
    the file and the line number of its first data row."""
    cap = read_capture(table_v)
    to_unit, std_factor = UNITS[unit]
    cols = dict(cap.columns)
    for a in AXES:
        cols[a] = to_unit(cols[a])
        cols[a + "_std"] = cols[a + "_std"] * std_factor
    meta = dict(cap.meta, accel_unit=unit)
    out = tmp_path / "table.csv"
    write_capture(out, Capture(meta, cols))
    lines = out.read_text().splitlines()
    h = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    if edit is not None:
        names = lines[h].split(",")
        for row, name, text in edit(cols):
            cells = lines[h + 1 + row].split(",")
            cells[names.index(name)] = text
            lines[h + 1 + row] = ",".join(cells)
        out.write_text("\n".join(lines) + "\n")
    return out, h + 2


def _refused_and_nothing_saved(tmp_path, capture, *needles):
    db = tmp_path / "station.db"
    assert run_station("--db", db, "devices", "add", "BENCH-1").returncode == 0
    res = run_station("calibrate", capture, "--save", "--device", "BENCH-1", "--db", db, subprocess_run=True)
    assert_one_line_refusal(res, *needles)
    with sqlite3.connect(db) as con:
        assert con.execute("select count(*) from calibrations").fetchone()[0] == 0


def test_the_testers_table_is_refused_on_its_first_row(table_v, tmp_path):
    """n = 1e19 and ax_std = 1e15 V in every row: the first bad cell on the first row is named."""
    capture, first = _table(
        table_v,
        tmp_path,
        edit=lambda cols: [(k, c, v) for k in range(12) for c, v in (("n", "1e19"), ("ax_std", "1e15"))],
    )
    _refused_and_nothing_saved(
        tmp_path, capture, f"{capture}:{first}: column 'n': '1e19' samples are more than any hold"
    )


@pytest.mark.parametrize("n", ["1e19", "2000000000", "1000000001"])
def test_more_samples_than_any_hold_averages_are_refused_on_their_line(table_v, tmp_path, n):
    capture, first = _table(table_v, tmp_path, edit=lambda cols: [(6, "n", n)])
    _refused_and_nothing_saved(
        tmp_path,
        capture,
        f"{capture}:{first + 6}: column 'n': '{n}' samples are more than any hold averages (at most 1e9, 11.6 days at 1 kHz)",
    )


@pytest.mark.parametrize("unit", list(UNITS))
def test_a_standard_deviation_wider_than_the_signal_is_refused_in_any_unit(table_v, tmp_path, unit):
    """5000 times the table's largest |a|: below the plausibility bound of the unit (1e7 m/s^2),
    so it is the table's own scale that refuses it."""

    def edit(cols):
        scale = max(np.abs(cols[a]).max() for a in AXES)
        return [(4, "az_std", f"{5000 * scale:.6g}")]

    capture, first = _table(table_v, tmp_path, unit, edit)
    _refused_and_nothing_saved(
        tmp_path,
        capture,
        f"{capture}:{first + 4}: column 'az_std': ",
        f" {unit} is more than 1000 times the largest magnitude of ax, ay, az in the table (",
    )


def test_the_testers_std_in_volts_is_refused(table_v, tmp_path):
    capture, first = _table(table_v, tmp_path, edit=lambda cols: [(2, "ax_std", "1e15")])
    _refused_and_nothing_saved(
        tmp_path, capture, f"{capture}:{first + 2}: column 'ax_std': 1e+15 V is more than 1000 times the largest"
    )


def test_the_bounds_themselves_and_a_shaky_hold_read(table_v, tmp_path):
    """n = 1e9 and n = 1, a std of 0, and a hold as wide as the signal itself (a vibrating bench)
    are numbers a bench can write."""

    def edit(cols):
        scale = max(np.abs(cols[a]).max() for a in AXES)
        return [(0, "n", "1000000000"), (1, "n", "1"), (2, "ay_std", "0"), (3, "ax_std", f"{999 * scale:.6g}")]

    capture, _ = _table(table_v, tmp_path, "counts", edit)
    got = read_capture(capture).columns
    assert got["n"][0] == 1e9 and got["n"][1] == 1 and got["ay_std"][2] == 0 and got["ax_std"][3] > 3e7


def test_the_writer_refuses_what_the_reader_refuses(table_v, tmp_path):
    cap = read_capture(table_v)
    many = dict(cap.columns, n=np.where(np.arange(12) == 3, 5e9, cap.columns["n"]))
    with pytest.raises(InputError, match="column 'n', row 4: 5e\\+09 samples are more than any hold"):
        write_capture(tmp_path / "a.csv", Capture(dict(cap.meta), many))
    wide = dict(cap.columns, ay_std=np.where(np.arange(12) == 7, 1e15, cap.columns["ay_std"]))
    with pytest.raises(InputError, match="column 'ay_std', row 8: 1e\\+15 V is more than 1000 times"):
        write_capture(tmp_path / "b.csv", Capture(dict(cap.meta), wide))
    assert not (tmp_path / "a.csv").exists() and not (tmp_path / "b.csv").exists()


def test_every_real_table_reads_and_so_do_tables_of_averages_of_every_real_recording(shared_data, tmp_path):
    """The published tables in ../shared/data (SOURCE.md: Wang & Li 2021's Table 1) read; so does a
    table of averages of each real time series there (MPU-6050 and Xsens counts, m/s^2 and deg/s,
    g, deg/s and gauss with temp_c: 500-sample holds, moving ones included, with n and every
    column's std): their widest std is 2 times the largest mean of its triad (measured), far
    inside the bound."""
    captures = sorted(shared_data.glob("*/*.capture.csv"))
    assert len(captures) >= 13
    tables = 0
    for path in captures:
        cap = read_capture(path)
        if not cap.is_time_series:
            tables += 1
            continue
        k = 500
        rows = cap.n_rows // k * k
        cols: dict[str, np.ndarray] = {"n": np.full(rows // k, float(k))}
        for name, col in cap.columns.items():
            if name in ("t", "position"):
                continue
            held = np.asarray(col[:rows], dtype=float).reshape(-1, k)
            cols[name] = held.mean(axis=1)
            cols[name + "_std"] = held.std(axis=1, ddof=1)
        meta = {key: v for key, v in cap.meta.items() if key != "sample_rate_hz"}
        out = tmp_path / path.name
        write_capture(out, Capture(meta, cols))
        back = read_capture(out)
        assert back.n_rows == rows // k and set(back.columns) == set(cols), path
    assert tables >= 1


def _streamed(path, rows: int) -> int:
    """Every chunk of ``path`` through the streaming reader (the one `station record` reads
    captures with), ``rows`` rows at a time: the rows read."""
    _, _, chunks = iter_capture_chunks(path, rows=rows)
    return sum(len(chunk["n"]) for chunk in chunks)


@pytest.mark.parametrize("rows", [1, 5, 1000])
def test_the_streaming_reader_refuses_a_wide_std_on_the_line_the_reader_names(table_v, tmp_path, rows):
    """The streaming reader applied the per-cell bounds (n above 1e9) but not the whole-table one:
    ax_std = 1e15 V streamed through in full (qa-s25b). Both readers now judge it by one
    implementation (WideStd) and name the same line, whatever the chunk size."""
    capture, first = _table(table_v, tmp_path, edit=lambda cols: [(2, "ax_std", "1e15")])
    with pytest.raises(InputError) as whole:
        read_capture(capture)
    with pytest.raises(InputError) as streamed:
        _streamed(capture, rows)
    assert str(streamed.value) == str(whole.value)
    assert str(streamed.value).startswith(f"{capture}:{first + 2}: column 'ax_std': 1e+15 V is more than 1000 times")


@pytest.mark.parametrize("rows", [1, 5, 1000])
def test_the_bound_is_the_whole_tables_in_both_readers(table_v, tmp_path, rows):
    """The bound comes from the whole table: a std on row 1 that is 5000 times every mean before
    it but under 1000 times a larger mean on a later row reads; the first of several rows over
    the final bound is named, not the widest, nor an earlier one only over the bound so far."""

    def quiet_until_the_last_row(cols):
        peak = max(np.abs(cols[a]).max() for a in AXES)
        small = {a: f"{1e-3 * peak:.6g}" for a in AXES}  # every mean but the last row's is tiny
        edits = [(k, a, small[a]) for k in range(11) for a in AXES]
        return edits + [(1, "ay_std", f"{5 * peak:.6g}"), (11, "ax", f"{peak:.6g}")]

    capture, _ = _table(table_v, tmp_path, edit=quiet_until_the_last_row)
    assert read_capture(capture).n_rows == 12 and _streamed(capture, rows) == 12

    def two_over(cols):
        peak = max(np.abs(cols[a]).max() for a in AXES)
        return [(3, "az_std", f"{2000 * peak:.6g}"), (5, "ax_std", f"{9000 * peak:.6g}"), (1, "ay_std", "1e-9")]

    capture, first = _table(table_v, tmp_path, edit=two_over)
    with pytest.raises(InputError) as whole:
        read_capture(capture)
    with pytest.raises(InputError) as streamed:
        _streamed(capture, rows)
    assert str(streamed.value) == str(whole.value)
    assert str(streamed.value).startswith(f"{capture}:{first + 3}: column 'az_std': ")
