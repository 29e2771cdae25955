"""A capture's ``# device:`` line holding a control character (an ESC sequence, a bell, a
bidi override). Before, the reader kept it: `calibrate --save` stored the device as
``IMU\\x1b[31mRED`` and every view showed it escaped, while `station import --device` refuses
the same text. Now the reader refuses it on the metadata's line, in import's words. An outside
tester's finding (branch qa-s24d)."""

from __future__ import annotations

import sqlite3

import pytest

from station.capture import read_capture
from tests.station_run import assert_one_line_refusal, run_station


def _with_device(tmp_path, device: str):
    """A simulated P1 table of averages whose ``# device:`` line holds ``device``; the file and
    that line's number."""
    src = tmp_path / "p1.csv"
    res = run_station(
        "simulate", "--procedure", "accel-tabletop", "--out", src, "--seed", "5", "--option", "averages=1"
    )
    assert res.returncode == 0, res.stderr
    lines = src.read_text().splitlines()
    k = next(i for i, line in enumerate(lines) if line.startswith("# device:"))
    lines[k] = f"# device: {device}"
    out = tmp_path / "device.csv"
    out.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return out, k + 1


@pytest.mark.parametrize(
    ("device", "shown"),
    [
        ("IMU\x1b[31mRED", "'IMU\\x1b[31mRED'"),
        ("IMU\x07-42", "'IMU\\x07-42'"),
        ("IMU\u202e24", "'IMU\\u202e24'"),
        ("IMU\t42", "'IMU\\t42'"),
    ],
)
def test_a_device_line_with_a_control_character_is_refused_on_its_line(tmp_path, device, shown):
    capture, line = _with_device(tmp_path, device)
    db = tmp_path / "station.db"
    res = run_station("calibrate", capture, "--save", "--db", db, subprocess_run=True)
    assert_one_line_refusal(
        res,
        f"{capture}:{line}: metadata 'device': {shown}: a capture's device cannot hold a control character",
    )
    assert "\x1b" not in res.stderr and "\x07" not in res.stderr
    if db.exists():
        with sqlite3.connect(db) as con:
            assert con.execute("select count(*) from calibrations").fetchone()[0] == 0


def test_import_refuses_the_same_device_in_the_same_words(tmp_path):
    """One rule, one wording: the reader's line ends as import's refusal of ``--device`` does."""
    capture, _ = _with_device(tmp_path, "IMU\x1b[31mRED")
    res = run_station("inspect", capture, subprocess_run=True)
    src = tmp_path / "bench.csv"
    src.write_text("\n".join(["time_s,ax,ay,az"] + [f"{i * 0.01:.2f},0.1,-0.2,9.8" for i in range(50)]) + "\n")
    imp = run_station(
        "import", src, "--procedure", "accel-tabletop", "--map", "t=time_s,ax=ax,ay=ay,az=az",
        "--unit", "accel=m/s^2,t=s", "--device", "IMU\x1b[31mRED", "--out", tmp_path / "o.csv",
    )  # fmt: skip
    assert_one_line_refusal(imp, "--device")
    assert_one_line_refusal(res, f"{capture}:")
    assert res.stderr.split("'IMU\\x1b[31mRED': ")[1] == imp.stderr.split("'IMU\\x1b[31mRED': ")[1]


def test_printable_device_ids_still_read(tmp_path):
    """Spaces inside, non-ASCII letters, punctuation: a device id, kept as written."""
    for device in ("IMU 0042 rev B", "Größe-Ω/7 (bench #2)", "日本-1"):
        capture, _ = _with_device(tmp_path, device)
        assert read_capture(capture).meta["device"] == device


@pytest.mark.parametrize(
    ("line", "says"),
    [
        ("# operator: Bob\x1b[31mRED", "metadata 'operator': 'Bob\\x1b[31mRED': a capture's metadata cannot hold"),
        ("# notes: left\tright", "metadata 'notes': 'left\\tright': a capture's metadata cannot hold"),
        ("# op\x1bx: 1", "metadata 'op\\x1bx': '1': a capture's metadata cannot hold"),
    ],
)
def test_any_metadata_line_with_a_control_character_is_refused_on_its_line(tmp_path, line, says):
    """Any other key too (the format keeps unknown keys): before, such a capture was saved and
    `export-capture` of it then failed, as the writer refuses what it cannot give back."""
    capture, device_line = _with_device(tmp_path, "IMU-0042")
    lines = capture.read_text().splitlines()
    lines.insert(device_line, line)
    capture.write_text("\n".join(lines) + "\n", encoding="utf-8")
    db = tmp_path / "station.db"
    res = run_station("calibrate", capture, "--save", "--db", db, subprocess_run=True)
    assert_one_line_refusal(res, f"{capture}:{device_line + 1}: {says}")
    assert not db.exists() or sqlite3.connect(db).execute("select count(*) from calibrations").fetchone()[0] == 0
