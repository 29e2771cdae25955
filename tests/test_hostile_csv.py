"""Plain CSV files an outside tester feeds `station import`, where the capture reader's own
checks do not reach: each is refused with one line naming the file and line, exit status 2,
nothing written.
"""

from __future__ import annotations

import pytest

from tests.station_run import assert_one_line_refusal, run_station


@pytest.mark.parametrize("mapping", [("--map", "t=time_s,ax=ax,ay=ay,az=az"), ()])
def test_import_refuses_a_mapped_column_name_that_appears_twice(tmp_path, mapping):
    """Two header columns named 'ax': the first was taken without a word. Now the line of the
    header and both column numbers are named (map it by number instead)."""
    rows = ["time_s,ax,ax,ay,az"] + [f"{i * 0.01:.2f},0.01,5.0,0.02,1.0" for i in range(400)]
    if not mapping:
        rows[0] = "t,ax,ax,ay,az"
    src = tmp_path / "dup.csv"
    src.write_text("\n".join(rows) + "\n")
    out = tmp_path / "out.csv"
    res = run_station("import", src, "--procedure", "accel-tabletop", *mapping, "--unit", "accel=g,t=s", "--out", out)
    assert_one_line_refusal(res, f"{src}:1: ", "'ax'", "columns 2 and 3")
    assert not out.exists()


@pytest.mark.parametrize("encoding", ["utf-16-le", "utf-16-be"])
def test_utf16_text_is_named_as_such(tmp_path, encoding):
    """UTF-16 without its byte-order mark was refused as "NUL byte: binary data"; it is text in
    another encoding, and the line says so. (With the mark, as Excel's "Unicode Text" saves it,
    it is read: tests/test_import_encodings.py.)"""
    text = "time_s,ax,ay,az\n" + "".join(f"{i * 0.01:.2f},0.01,0.02,1.0\n" for i in range(200))
    src = tmp_path / "u16.csv"
    src.write_bytes(text.encode(encoding))
    res = run_station(
        "import", src, "--procedure", "accel-tabletop", "--map", "t=time_s,ax=ax,ay=ay,az=az",
        "--unit", "accel=g,t=s", "--out", tmp_path / "o.csv",
    )  # fmt: skip
    assert_one_line_refusal(res, f"{src}:1: ", "UTF-16 text", "UTF-8")
    cap = tmp_path / "u16.capture.csv"
    cap.write_bytes(("# station-capture: 1\n# procedure: gyro-drift\nt,gx,gy,gz\n0,1,2,3\n").encode(encoding))
    assert_one_line_refusal(run_station("inspect", cap), f"{cap}:1: ", "UTF-16 text", "UTF-8")


def test_of_several_bad_metadata_lines_the_first_is_named(tmp_path):
    """NaN in two numeric keys: the refusal named line 4 (latitude_deg) before line 3
    (sample_rate_hz), in the order the reader checks keys, not the file's."""
    rows = ["# station-capture: 1", "# procedure: gyro-drift", "# sample_rate_hz: nan", "# latitude_deg: NaN"]
    path = tmp_path / "nan.csv"
    path.write_text("\n".join(rows + ["t,gx,gy,gz", "0,1,2,3", "0.1,1,2,3"]) + "\n")
    assert_one_line_refusal(run_station("inspect", path), f"{path}:3: metadata 'sample_rate_hz': 'nan' is not a number")


def test_a_head_of_endless_metadata_lines_is_refused_at_its_limit(tmp_path):
    """3 million '# key: value' lines (40 MB) took 56 s and 0.9 GB to read into the metadata;
    a capture's head holds a few hundred (the firmware parameters in use at most), so the
    reader stops at 65 536 metadata lines, naming the line."""
    from station.capture import MAX_META_LINES

    path = tmp_path / "head.csv"
    with open(path, "w") as f:
        f.write("# station-capture: 1\n# procedure: gyro-drift\n")
        f.writelines(f"# k{i}: v\n" for i in range(MAX_META_LINES + 10))
        f.write("t,gx,gy,gz\n0,1,2,3\n0.1,1,2,3\n")
    assert_one_line_refusal(
        run_station("inspect", path), f"{path}:{MAX_META_LINES + 2}: ", "more than 65536 metadata lines"
    )


@pytest.mark.parametrize(
    ("keys", "line", "says"),
    [
        (("PROCEDURE: compass", "procedure: accel-tabletop"), 3, "'procedure': the same key as 'PROCEDURE' on line 2"),
        (("MAG_UNIT: uT", "Mag_Unit: nT"), 3, "'Mag_Unit': the same key as 'MAG_UNIT' on line 2"),
    ],
)
def test_one_metadata_key_spelled_twice_in_other_letter_case_is_a_duplicate(tmp_path, keys, line, says):
    """A key of the format in other letter case is that key (README), so 'PROCEDURE: compass'
    above 'procedure: accel-tabletop' is the key given twice; the second spelling was kept as
    an unknown key and ignored without a word, so the capture was read as one of the two
    procedures, or in one of the two units, by the spelling alone."""
    path = tmp_path / "twice.csv"
    rows = [f"{i * 0.01:.2f},{i % 7},1,2" for i in range(50)]
    body = ["# station-capture: 1", *(f"# {k}" for k in keys), "# procedure: compass" if "MAG" in keys[0] else ""]
    path.write_text("\n".join([*filter(None, body), "t,mx,my,mz", *rows]) + "\n")
    for command in ("inspect", "calibrate", "diagnose"):
        assert_one_line_refusal(run_station(command, path), f"{path}:{line}: duplicate metadata key {says}")


def test_the_writer_refuses_one_key_spelled_twice_as_the_reader_would(tmp_path):
    import numpy as np

    from station.capture import Capture, write_capture
    from station.errors import InputError

    path = tmp_path / "w.csv"
    cap = Capture({"procedure": "compass", "MAG_UNIT": "uT", "mag_unit": "nT"}, {"mx": np.array([1.0, 2.0])})
    with pytest.raises(InputError, match="'MAG_UNIT' and 'mag_unit' are one key to the reader"):
        write_capture(path, cap)
    assert not path.exists()


@pytest.mark.parametrize("command", ["inspect", "calibrate", "diagnose"])
def test_a_last_line_without_its_line_end_is_warned_about(tmp_path, command):
    """A capture cut short mid-row ('...,26.' of '...,26.125'): the row read as if whole, its
    last value changed, without a word. A last line with no line end is how a cut file ends
    (though some editors save a whole file so): the row is kept and a warning says to check it.
    A file that ends with its line end gets no warning."""
    made = run_station("simulate", "--procedure", "gyro-drift", "--out", tmp_path / "whole.csv", "--seed", "400016")
    assert made.returncode == 0, made.stderr
    data = (tmp_path / "whole.csv").read_bytes()
    cut = tmp_path / "cut.csv"
    cut.write_bytes(data[: data.rindex(b".", 0, len(data) // 2) + 2])  # one decimal after a '.': a value cut
    n_lines = cut.read_bytes().count(b"\n") + 1
    args = ["--no-plots"] if command == "diagnose" else []
    res = run_station(command, cut, *args)
    assert res.returncode == 0, res.stderr
    warned = [ln for ln in res.stderr.splitlines() if ": warning: " in ln]
    assert warned == [f"station: {cut}: warning: the last line ({n_lines}) has no line end: a file cut short "
                      "(a copy or a write stopped part-way) ends so, and then its last value may be cut too "
                      "(kept as read)"]  # fmt: skip
    assert "no line end" not in res.stdout
    whole = run_station(command, tmp_path / "whole.csv", *args)
    assert whole.returncode == 0 and "no line end" not in whole.stderr
