"""Captures and CSV files as other people's tools write them: a spreadsheet's save, pandas and
numpy writers with their own separators and line ends, a writer killed mid-line. Each is read
correctly, or refused with one line naming the file, the line and what is wrong (exit 2,
nothing on stdout, no output file). What the older hostile-input tests already cover
(test_hostile_*.py, test_capture_variants.py, test_capture.py) is not repeated here.
"""

from __future__ import annotations

import csv
import io
import json

import pytest

from tests.station_run import assert_one_line_refusal, run_station


@pytest.fixture(scope="module")
def gyro_capture(tmp_path_factory):
    """A short P4 capture as the station writes it, and its calibration."""
    folder = tmp_path_factory.mktemp("p4")
    path = folder / "p4.csv"
    made = run_station("simulate", "--procedure", "gyro-drift", "--out", path, "--seed", "400417")
    assert made.returncode == 0, made.stderr
    res = run_station("calibrate", path, "--json")
    assert res.returncode == 0, res.stderr
    return path, json.loads(res.stdout)


def spreadsheet_save(text: str) -> str:
    """What a spreadsheet (Excel, LibreOffice Calc) writes after opening a CSV and saving it as
    CSV: every row padded with empty cells to the widest row, CRLF line ends."""
    rows = list(csv.reader(io.StringIO(text)))
    width = max(len(r) for r in rows)
    out = io.StringIO()
    csv.writer(out, lineterminator="\r\n").writerows(r + [""] * (width - len(r)) for r in rows)
    return out.getvalue()


def test_a_capture_saved_again_by_a_spreadsheet_reads_as_the_capture(tmp_path, gyro_capture):
    """The metadata lines come back as '# device: SIM-GYR,,,,,,,' (one cell, padded to the
    table's width). Before: refused on line 1 as "unsupported capture version '1,,,,,,,'"."""
    path, result = gyro_capture
    saved = tmp_path / "saved.csv"
    saved.write_text(spreadsheet_save(path.read_text()), newline="")
    assert saved.read_text().splitlines()[0].startswith("# station-capture: 1,,")
    res = run_station("calibrate", saved, "--json")
    assert res.returncode == 0, res.stderr
    again = json.loads(res.stdout)
    assert again["params"] == result["params"]
    assert again["device"] == result["device"]


def _bench_csv(n: int = 400) -> str:
    """A bench logger's CSV as pandas writes it (DataFrame.to_csv)."""
    import numpy as np
    import pandas as pd

    rng = np.random.default_rng(400418)
    frame = pd.DataFrame(
        {
            "time_s": np.arange(n) * 0.01,
            "acc_x": rng.normal(0, 0.01, n),
            "acc_y": rng.normal(0, 0.01, n),
            "acc_z": 9.81 + rng.normal(0, 0.01, n),
        }
    )
    return frame.to_csv(index=False)


BENCH_MAP = ["--map", "t=time_s,ax=acc_x,ay=acc_y,az=acc_z", "--unit", "accel=m/s^2"]


@pytest.mark.parametrize("cut", [0, 3], ids=["whole", "cut-mid-value"])
def test_import_of_a_csv_whose_last_line_has_no_line_end_warns_that_it_may_be_cut(tmp_path, cut):
    """A bench CSV copied while its logger still wrote it, or the logger killed: the last value
    is cut ('9.8123' read as '9.8'). The capture reader warns of a last line without its line
    end; the importer read it as whole, without a word (before: exit 0, stderr empty)."""
    text = _bench_csv()
    cut_text = text[: len(text) - 1 - cut]  # without the final line end, and `cut` characters more
    src = tmp_path / "bench.csv"
    src.write_text(cut_text, newline="")
    out = tmp_path / "bench.capture.csv"
    res = run_station("import", src, "--procedure", "accel-tabletop", "--out", out, *BENCH_MAP)
    assert res.returncode == 0, res.stderr
    n_lines = cut_text.count("\n") + 1
    assert f"warning: the last line ({n_lines}) has no line end" in res.stderr, res.stderr
    assert res.stderr.count("\n") == 1
    whole = tmp_path / "whole.csv"
    whole.write_text(text, newline="")
    again = run_station(
        "import", whole, "--procedure", "accel-tabletop", "--out", tmp_path / "w.capture.csv", *BENCH_MAP
    )
    assert again.returncode == 0 and "line end" not in again.stderr, again.stderr


def test_import_of_an_euroc_file_cut_mid_line_warns_too(tmp_path):
    """The same for an EuRoC IMU file (mav0/imu0/data.csv), which calibrate also reads directly."""
    import numpy as np

    rng = np.random.default_rng(400419)
    head = "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
    head += "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]\n"
    rows = [
        f"{1403636579758555392 + 5_000_000 * i},{','.join(repr(float(x)) for x in rng.normal(0, 1e-3, 3))},"
        f"{','.join(repr(float(x)) for x in rng.normal((0.0, 0.0, 9.81), 0.01))}"
        for i in range(300)
    ]
    src = tmp_path / "data.csv"
    src.write_text(head + "\n".join(rows)[:-3], newline="")  # no final line end, the last value cut
    res = run_station("import", src, "--procedure", "gyro-drift", "--out", tmp_path / "e.capture.csv")
    assert res.returncode == 0, res.stderr
    assert f"warning: the last line ({len(rows) + 1}) has no line end" in res.stderr, res.stderr


@pytest.mark.parametrize(
    "sep, decimal, said",
    [(";", ".", "';'"), (";", ",", "';'"), ("\t", ".", "tabs")],
    ids=["semicolon", "semicolon-decimal-comma", "tab"],
)
def test_a_capture_written_with_another_separator_is_refused_at_its_header_saying_so(
    tmp_path, gyro_capture, sep, decimal, said
):
    """pandas' to_csv(sep=';', decimal=',') as a spreadsheet of a decimal-comma locale writes it,
    or sep='\\t', under the capture's metadata lines. Before: 'line 16: too many fields: 8 where
    the header has 1 columns' (the first data row, split at its decimal commas), or the whole
    header called one column name that "is not plain text"."""
    import pandas as pd

    path, _ = gyro_capture
    text = path.read_text()
    meta = "".join(ln for ln in text.splitlines(keepends=True) if ln.startswith("#"))
    header_line = meta.count("\n") + 1
    frame = pd.read_csv(path, comment="#")
    out = tmp_path / "other.csv"
    out.write_text(meta + frame.to_csv(index=False, sep=sep, decimal=decimal))
    for command in ("calibrate", "diagnose", "inspect"):
        res = run_station(command, out)
        assert_one_line_refusal(res, f"{out}:{header_line}:", said, "comma")


def _cut_mid_row(text: str) -> str:
    """``text`` as a writer killed mid-row leaves it: the last row's first two fields only."""
    last = text.rstrip("\n").rsplit("\n", 1)[1]
    cut = len(text.rstrip("\n")) - len(last) + len(",".join(last.split(",")[:2]))
    return text[:cut]


def test_a_capture_cut_mid_row_is_refused_saying_the_file_is_cut(tmp_path, gyro_capture):
    """A capture whose writer was killed mid-row (or one still being appended to): the last line
    holds 2 of 8 fields and no line end. Before: 'too few fields: 2 where the header has 8
    columns', as for a row short in the middle of a file; the line now says the file is cut."""
    path, _ = gyro_capture
    cut = tmp_path / "cut.csv"
    cut.write_text(_cut_mid_row(path.read_text()))
    n_lines = cut.read_text().count("\n") + 1
    for command in ("calibrate", "diagnose", "inspect"):
        res = run_station(command, cut)
        assert_one_line_refusal(res, f"{cut}:{n_lines}: too few fields: 2 where the header has 8", "no line end")
    whole_but_short = tmp_path / "short.csv"  # the same short row with its line end: no word of a cut
    whole_but_short.write_text(cut.read_text() + "\n")
    res = run_station("inspect", whole_but_short)
    assert_one_line_refusal(res, f"{whole_but_short}:{n_lines}: too few fields")
    assert "line end" not in res.stderr


def test_import_of_a_csv_cut_mid_row_is_refused_saying_the_file_is_cut(tmp_path):
    src = tmp_path / "bench.csv"
    src.write_text(_cut_mid_row(_bench_csv()), newline="")
    n_lines = src.read_text().count("\n") + 1
    out = tmp_path / "bench.capture.csv"
    res = run_station("import", src, "--procedure", "accel-tabletop", "--out", out, *BENCH_MAP)
    assert_one_line_refusal(res, f"{src}:{n_lines}: 2 fields where the header has 4", "no line end")
    assert not out.exists()


@pytest.mark.parametrize("sep", [";", "\t"], ids=["semicolon", "tab"])
def test_import_reads_decimal_commas_where_the_separator_is_not_a_comma(tmp_path, sep):
    """A bench CSV from a decimal-comma locale (pandas to_csv(sep=';', decimal=','), a German
    spreadsheet's save): '0,01;-0,0123;9,81'. Before: refused, "column 't': '0,0' is not a
    number". Now read as the same numbers as the '.' file."""
    import io

    import pandas as pd

    frame = pd.read_csv(io.StringIO(_bench_csv()))
    plain, local = tmp_path / "plain.csv", tmp_path / "local.csv"
    plain.write_text(frame.to_csv(index=False))
    local.write_text(frame.to_csv(index=False, sep=sep, decimal=","))
    outs = []
    for src in (plain, local):
        out = tmp_path / f"{src.stem}.capture.csv"
        res = run_station("import", src, "--procedure", "accel-tabletop", "--out", out, *BENCH_MAP)
        assert res.returncode == 0, res.stderr
        outs.append([ln for ln in out.read_text().splitlines() if not ln.startswith("# source")])
    assert outs[0] == outs[1]


def test_import_refuses_a_file_that_mixes_decimal_commas_and_points(tmp_path):
    """'1,5' on one line and '1.234' on another: a thousands separator or a decimal point, no way
    to tell; one line names where the second mark appears."""
    src = tmp_path / "mixed.csv"
    src.write_text("time_s;acc_x;acc_y;acc_z\n0;0,01;0,02;9,81\n0,01;0.011;0,02;9,81\n")
    out = tmp_path / "mixed.capture.csv"
    res = run_station("import", src, "--procedure", "accel-tabletop", "--out", out, *BENCH_MAP)
    assert_one_line_refusal(res, f"{src}:3:", "'0.011'", "decimal comma", "line 2")
    assert not out.exists()


def test_p1_holds_numbered_as_pandas_writes_integers_with_gaps_keep_their_positions(tmp_path):
    """A P1 capture whose `position` numbers the holds 1..12 in the source's order, the rows
    between holds left empty: pandas holds such a column as float and writes '1.0', '2.0', ...
    Before: '1.0' was no position P1 knows, the labels were silently unused (gauge
    upper-triangular, n_labelled_positions 0, B off by 0.11 m/s² from the '1' file's) and no
    warning said so. capture-format.md: position is an integer or a label."""
    import pandas as pd

    from solvers.tabletop import P1_POSITIONS

    made = tmp_path / "p1.csv"
    res = run_station(
        "simulate", "--procedure", "accel-tabletop", "--out", made, "--seed", "400420", "--option", "hold_s=5"
    )
    assert res.returncode == 0, res.stderr
    text = made.read_text()
    meta = "".join(ln for ln in text.splitlines(keepends=True) if ln.startswith("#"))
    frame = pd.read_csv(made, comment="#", keep_default_na=False)
    number = {label: k for k, label in enumerate(P1_POSITIONS, 1)}  # 1 = X up, ... (the source's order)
    frame["position"] = [number.get(p) for p in frame["position"]]  # moves between holds: None
    floats = tmp_path / "floats.csv"
    floats.write_text(meta + frame.to_csv(index=False))
    assert "\n0.0,1.0," in floats.read_text()
    ints = tmp_path / "ints.csv"
    frame["position"] = frame["position"].astype("Int64")
    ints.write_text(meta + frame.to_csv(index=False))
    assert "\n0.0,1," in ints.read_text()
    results = []
    for path in (ints, floats):
        res = run_station("calibrate", path, "--json")
        assert res.returncode == 0, res.stderr
        results.append(json.loads(res.stdout))
    assert results[0]["gauge"] == "table" and results[0]["n_labelled_positions"] == 12
    for key in ("gauge", "n_labelled_positions", "params", "uncertainty"):
        assert results[1][key] == results[0][key], key


def _ros1_bag(tmp_path, change):
    """A ROS 1 bag written by rosbags' own writer (the IMU and magnetometer messages of the ROS
    import tests), its message list passed through ``change`` first; and the untouched list."""
    import numpy as np
    from rosbags.typesys import Stores, get_typestore

    from tests.test_import_ros import _messages, write_ros1

    ts = get_typestore(Stores.ROS1_NOETIC)
    msgs, _ = _messages(ts, np.random.default_rng(400421), n_imu=1000)
    path = tmp_path / "run.bag"
    write_ros1(path, change(ts, msgs))
    return path, msgs


def _import_bag(tmp_path, path):
    out = tmp_path / "bag.capture.csv"
    res = run_station("import", path, "--procedure", "gyro-drift", "--out", out, "--topic", "imu=/imu/data")
    assert res.returncode == 0, res.stderr
    return res, [ln for ln in out.read_text().splitlines() if not ln.startswith("#")]


def test_a_bag_that_recorded_every_imu_message_twice_keeps_each_sample_once(tmp_path):
    """Two recorders (or a topic bridged twice) into one bag: every Imu message twice, same
    stamp, same values. Before: imported with 2 rows per sample, without a word (the mean kept,
    its σ from twice the samples: √2 too small). The MAVLink telemetry reader already kept
    such repeats once; now every log reader does."""
    twice, msgs = _ros1_bag(
        tmp_path, lambda ts, m: sorted(m + [x for x in m if x[0] == "/imu/data"], key=lambda x: x[2])
    )
    res, rows = _import_bag(tmp_path, twice)
    (tmp_path / "once").mkdir()
    once, _ = _ros1_bag(tmp_path / "once", lambda ts, m: m)
    _, rows_once = _import_bag(tmp_path / "once", once)
    assert rows == rows_once
    assert "1000 repeated gyro samples (same time and values) read once" in res.stderr, res.stderr


def test_imu_messages_stamped_out_of_time_order_are_said(tmp_path):
    """A driver whose stamps jump back (a clock reset, two publishers): every 10th Imu message
    stamped 0.5 s early. The rows are put in time order, as before, but no longer silently."""

    def early(ts, msgs):
        import copy

        Time = ts.types["builtin_interfaces/msg/Time"]
        out = []
        for i, (topic, typ, ns, msg) in enumerate(msgs):
            if topic == "/imu/data" and i % 10 == 0 and i > 200:
                msg = copy.deepcopy(msg)
                t = ns - 500_000_000
                msg.header.stamp = Time(sec=t // 10**9, nanosec=t % 10**9)
            out.append((topic, typ, ns, msg))
        return out

    path, _ = _ros1_bag(tmp_path, early)
    res, _ = _import_bag(tmp_path, path)
    said = [ln for ln in res.stderr.splitlines() if "earlier than the sample before" in ln]
    assert len(said) == 2, res.stderr  # the gyro and the accelerometer of the same messages
    assert "by up to 0.495 s" in said[0], said  # 0.5 s early, less the 5 ms step to the sample before


def _rewrite_with_csv_module(path, out, quoting):
    """The capture at ``path`` written again by Python's csv module with ``quoting`` (R's
    write.table(quote=TRUE) writes as QUOTE_NONNUMERIC does): the metadata lines as they were,
    the header and every row through csv.writer, numbers as floats, labels as text."""
    text = path.read_text()
    meta = [ln for ln in text.splitlines() if ln.startswith("#")]
    rows = list(csv.reader(io.StringIO("\n".join(ln for ln in text.splitlines() if not ln.startswith("#")))))
    header = rows[0]
    buf = io.StringIO()
    w = csv.writer(buf, quoting=quoting, lineterminator="\n")
    w.writerow(header)
    for r in rows[1:]:
        w.writerow([c if name == "position" else (float(c) if c else "") for name, c in zip(header, r)])
    out.write_text("\n".join(meta) + "\n" + buf.getvalue())


@pytest.mark.parametrize("quoting", [csv.QUOTE_NONNUMERIC, csv.QUOTE_ALL], ids=["quote-nonnumeric", "quote-all"])
def test_a_capture_whose_fields_are_quoted_as_csv_writers_quote_them_reads_as_the_capture(tmp_path, quoting):
    """CSV's quotes around a field ('"t","position","ax"', '"x_up"', with QUOTE_ALL '"0.01"') are
    no part of it. Before: refused, column name '"position"' is not plain text."""
    made = tmp_path / "p2.csv"
    res = run_station("simulate", "--procedure", "accel-centrifuge", "--out", made, "--seed", "400422")
    assert res.returncode == 0, res.stderr
    quoted = tmp_path / "quoted.csv"
    _rewrite_with_csv_module(made, quoted, quoting)
    assert '"position"' in quoted.read_text() and ',"1",' not in quoted.read_text()
    results = []
    for path in (made, quoted):
        res = run_station("calibrate", path, "--json")
        assert res.returncode == 0, res.stderr
        results.append(json.loads(res.stdout))
    assert results[1]["params"] == results[0]["params"]
    assert results[1]["n_positions"] == results[0]["n_positions"]


@pytest.mark.parametrize("missing", ["NA", "N/A", "#N/A", "null", "None"])
def test_a_missing_value_as_other_tools_spell_it_is_refused_with_the_way_to_write_it(tmp_path, gyro_capture, missing):
    """R's write.table writes a missing value as NA, a spreadsheet as #N/A, JSON-minded tools
    null or None. Each is refused as 'nan' is, saying to leave the field empty (capture-format.md:
    empty field = missing value); before, 'NA' was only 'not a number'."""
    path, _ = gyro_capture
    lines = path.read_text().splitlines(keepends=True)
    first_row = next(i for i, ln in enumerate(lines) if not ln.startswith("#")) + 1
    fields = lines[first_row + 5].split(",")
    fields[-1] = missing + "\n"  # temp_c
    lines[first_row + 5] = ",".join(fields)
    bad = tmp_path / "missing.csv"
    bad.write_text("".join(lines))
    res = run_station("calibrate", bad)
    assert_one_line_refusal(
        res, f"{bad}:{first_row + 6}: column 'temp_c': '{missing}' is not allowed", "leave the field empty"
    )


def test_a_telemetry_log_of_two_vehicles_reads_one_vehicles_imu_and_says_so(tmp_path):
    """A ground station's .tlog with two vehicles on the link (MAVLink system ids 1 and 2, both
    sending RAW_IMU), written by pymavlink's own log writer. Before: the two IMUs interleaved
    into one capture row by row (ax 10, 990, 10, 990, ... mG), without a word. Now the vehicle
    with the most IMU messages (the first on a tie) is read, and a warning names the other."""
    import struct

    from pymavlink import mavutil

    from tests.test_import_ardupilot import PARAMS

    path = tmp_path / "two.tlog"
    log = mavutil.mavlogfile(str(path), write=True, source_system=1, source_component=1)
    mav = log.mav
    t0 = 1_700_000_000.0

    def at(t):
        log.write(struct.pack(">Q", int(t * 1e6)))

    for sysid in (1, 2):
        mav.srcSystem = sysid
        at(t0)
        mav.heartbeat_send(2, 3, 0, 0, 4)  # a quadrotor running ArduPilot
        for i, (name, value) in enumerate(PARAMS.items()):
            at(t0)
            mav.param_value_send(name.encode(), float(value) + sysid - 1, 9, len(PARAMS), i)
    for k in range(200):
        for sysid, acc in ((1, (10, -20, -1000)), (2, (990, 5, 30))):  # vehicle 2 lies on its side
            mav.srcSystem = sysid
            at(t0 + 0.1 + k * 0.02)
            mav.raw_imu_send(1_000_000 + k * 20_000 + 7_000 * (sysid - 1), *acc, 5, -6, 7, 200, -100, 400)
    log.close()
    out = tmp_path / "two.capture.csv"
    res = run_station("import", path, "--procedure", "gyro-drift", "--out", out)
    assert res.returncode == 0, res.stderr
    rows = [ln.split(",") for ln in out.read_text().splitlines() if not ln.startswith("#")]
    ax = {float(r[rows[0].index("ax")]) for r in rows[1:]}
    assert len(rows) - 1 == 200 and ax == {10.0}, (len(rows), ax)
    assert "system 2" in res.stderr and "left out" in res.stderr, res.stderr
    meta = dict(ln[2:].split(": ", 1) for ln in out.read_text().splitlines() if ln.startswith("# "))
    first = next(iter(PARAMS))
    assert float(meta[f"param.{first}"]) == pytest.approx(float(PARAMS[first]))  # vehicle 1's, not 2's


def test_an_imu_topic_carrying_two_sensors_frames_reads_one_and_says_so(tmp_path):
    """Two IMUs published on one topic (a relay, a mux), told apart only by header.frame_id.
    Before: their samples interleaved into one capture (az 9.8, -0.02, 9.8, ... m/s²), silently.
    Now the frame with the most messages (the first on a tie) is read and a warning names the
    other; the capture's frame_id is the one read."""

    def second_imu(ts, msgs):
        import copy

        Time = ts.types["builtin_interfaces/msg/Time"]
        extra = []
        for topic, typ, ns, msg in msgs:
            if topic == "/imu/data":
                other = copy.deepcopy(msg)
                other.header.frame_id = "imu2_link"
                other.linear_acceleration.x, other.linear_acceleration.z = 9.81, 0.0  # mounted on its side
                t = ns + 1_000_000
                other.header.stamp = Time(sec=t // 10**9, nanosec=t % 10**9)
                extra.append((topic, typ, t, other))
        return sorted(msgs + extra, key=lambda m: m[2])

    path, _ = _ros1_bag(tmp_path, second_imu)
    res, rows = _import_bag(tmp_path, path)
    az = [float(r.split(",")[3]) for r in rows[1:]]
    assert min(az) > 9.0, "the second IMU's rows are in the capture"
    assert "imu2_link" in res.stderr and "left out" in res.stderr, res.stderr
    out = (tmp_path / "bag.capture.csv").read_text()
    assert "# frame_id: imu_link\n" in out


@pytest.mark.parametrize("writer", ["numpy-savetxt", "pandas-na_rep-NaN", "R-NA"])
def test_import_reads_a_missing_value_as_the_writer_spells_it(tmp_path, writer):
    """numpy.savetxt writes a missing value as 'nan', pandas with na_rep='NaN' as 'NaN', R's
    write.csv as 'NA'. Before: refused, "column 'temp_c': 'nan' is not a number". Now read as
    the empty cell a pandas default export has there."""
    import io

    import numpy as np
    import pandas as pd

    frame = pd.read_csv(io.StringIO(_bench_csv()))
    frame["temp"] = 25.0
    frame.loc[7, "temp"] = np.nan
    empty, spelled = tmp_path / "empty.csv", tmp_path / "spelled.csv"
    empty.write_text(frame.to_csv(index=False))
    if writer == "numpy-savetxt":
        np.savetxt(spelled, frame.to_numpy(), delimiter=",", header=",".join(frame.columns), comments="")
    else:
        spelled.write_text(frame.to_csv(index=False, na_rep="NaN" if writer == "pandas-na_rep-NaN" else "NA"))
    assert "nan" in spelled.read_text().lower() or ",NA" in spelled.read_text()
    outs = []
    for src in (empty, spelled):
        out = tmp_path / f"{src.stem}.capture.csv"
        res = run_station(
            "import",
            src,
            "--procedure",
            "accel-tabletop",
            "--out",
            out,
            *BENCH_MAP[:1],
            BENCH_MAP[1] + ",temp_c=temp",
            *BENCH_MAP[2:],
        )
        assert res.returncode == 0, res.stderr
        rows = [ln.split(",") for ln in out.read_text().splitlines() if not ln.startswith("#")]
        outs.append([[float(c) if c else None for c in r] for r in rows[1:]])
    assert outs[0] == outs[1]


def test_a_csv_on_a_coarse_clock_keeps_repeated_quiet_samples(tmp_path):
    """t in whole milliseconds at 2 kHz: two samples share each stamp, and a quiet gyro in counts
    often reads the same three values twice. Those are samples, not a log fed twice: kept, and
    no 'repeated' warning."""
    lines = ["t_ms,gx,gy,gz"]
    for k in range(4000):
        lines.append(f"{k // 2},{k % 3 // 2},0,{(k // 7) % 2}")
    src = tmp_path / "coarse.csv"
    src.write_text("\n".join(lines) + "\n")
    out = tmp_path / "coarse.capture.csv"
    res = run_station(
        "import", src, "--procedure", "gyro-drift", "--out", out,
        "--map", "t=t_ms,gx=gx,gy=gy,gz=gz", "--unit", "gyro=counts,t=ms",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert "repeated" not in res.stderr, res.stderr
    assert sum(1 for ln in out.read_text().splitlines() if not ln.startswith("#")) - 1 == 4000


def test_imu_messages_that_all_carry_one_stamp_are_refused_as_having_no_time_axis(tmp_path):
    """A driver that stamps every Imu message with one time (set once at start-up). Before: 'fewer
    than 2 gyro samples where all sensors overlap', which sent one looking at the magnetometer."""

    def one_stamp(ts, msgs):
        import copy

        Time = ts.types["builtin_interfaces/msg/Time"]
        out = []
        for topic, typ, ns, msg in msgs:
            if topic == "/imu/data":
                msg = copy.deepcopy(msg)
                msg.header.stamp = Time(sec=1_700_000_000, nanosec=0)
            out.append((topic, typ, ns, msg))
        return out

    path, _ = _ros1_bag(tmp_path, one_stamp)
    out = tmp_path / "bag.capture.csv"
    res = run_station("import", path, "--procedure", "gyro-drift", "--out", out, "--topic", "imu=/imu/data")
    assert_one_line_refusal(res, str(path), "1000 gyro samples", "one time")
    assert not out.exists()
