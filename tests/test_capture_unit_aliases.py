"""Units spelt as other tools spell them (µT with the micro sign or the Greek mu, m/s2, dps)
are read as the unit they name: the same calibration as the spec's spelling, on real data."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
from station_run import ROOT, assert_one_line_refusal, run_station

DATA = Path(os.environ.get("STATION_SHARED") or ROOT.parent / "shared") / "data"


def _calibrated(path, *args) -> dict:
    res = run_station("calibrate", path, "--json", *args)
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout.replace(str(path), "FILE"))


def _respelt(src, dst, old: str, new: str) -> None:
    text = src.read_text(encoding="utf-8")
    assert old in text
    dst.write_text(text.replace(old, new, 1), encoding="utf-8")


@pytest.mark.parametrize(
    "old,new",
    [("# accel_unit: m/s^2", "# accel_unit: m/s2"), ("# gyro_unit: deg/s", "# gyro_unit: dps")],
)
def test_accel_and_gyro_units_as_other_tools_write_them(tmp_path, old, new):
    src = DATA / "imucal_ferraris" / "imucal_ferraris_labelled.capture.csv"
    plain, other = tmp_path / "plain.csv", tmp_path / "other.csv"
    _respelt(src, plain, old, old)
    _respelt(src, other, old, new)
    six = ("--method", "six-position")  # the capture's six labelled ±axis positions
    assert _calibrated(other, *six) == _calibrated(plain, *six)


def _in_microtesla(src, dst, unit: str) -> None:
    """The real compass capture (gauss) with its field columns in µT under ``unit``."""
    lines = src.read_text(encoding="utf-8").splitlines()
    out, header = [], None
    for line in lines:
        if line.startswith("#"):
            out.append(f"# mag_unit: {unit}" if line.startswith("# mag_unit:") else line)
        elif header is None:
            header = [c.strip() for c in line.split(",")]
            cols = [header.index(c) for c in ("mx", "my", "mz")]
            out.append(line)
        else:
            f = line.split(",")
            for k in cols:
                f[k] = repr(float(f[k]) * 100.0)
            out.append(",".join(f))
    dst.write_text("\n".join(out) + "\n", encoding="utf-8")


def test_microtesla_with_the_micro_sign_or_the_greek_mu(tmp_path):
    src = DATA / "sunsided_marg" / "sunsided_full_sphere.capture.csv"
    results = []
    for unit, name in (("uT", "plain"), ("\u00b5T", "micro"), ("\u03bcT", "mu")):
        path = tmp_path / f"{name}.csv"
        _in_microtesla(src, path, unit)
        results.append(_calibrated(path))
    assert results[0]["mag_unit"] == "uT"
    assert results[1] == results[0] and results[2] == results[0]


def test_a_unit_no_tool_writes_is_still_refused(tmp_path):
    src = DATA / "imucal_ferraris" / "imucal_ferraris_labelled.capture.csv"
    path = tmp_path / "bad.csv"
    _respelt(src, path, "# gyro_unit: deg/s", "# gyro_unit: furlongs/fortnight")
    assert_one_line_refusal(run_station("calibrate", path, "--json"), "gyro_unit", "furlongs/fortnight")


def test_a_metadata_key_in_other_letter_case_is_read_as_the_key(tmp_path):
    """'MAG_UNIT: uT' was ignored as an unknown key: the compass then calibrated in raw units."""
    src = DATA / "sunsided_marg" / "sunsided_full_sphere.capture.csv"
    plain, upper = tmp_path / "plain.csv", tmp_path / "upper.csv"
    _in_microtesla(src, plain, "uT")
    _respelt(plain, upper, "# mag_unit: uT", "# MAG_UNIT: uT")
    got = _calibrated(upper)
    assert got["mag_unit"] == "uT"
    assert got == _calibrated(plain)


def test_a_compass_capture_with_a_place_and_no_date_is_calibrated_unanchored(tmp_path):
    """A place without a date gives no IGRF field: calibrated as with no place, saying why
    (it was refused, and the whole capture lost for one missing metadata line)."""
    src = DATA / "sunsided_marg" / "sunsided_full_sphere.capture.csv"
    text = src.read_text(encoding="utf-8")
    date_line = next(line for line in text.splitlines() if line.startswith("# date:"))
    no_place = tmp_path / "no_place.csv"
    no_place.write_text(text.replace(date_line + "\n", ""), encoding="utf-8")
    no_date = tmp_path / "no_date.csv"
    no_date.write_text(text.replace(date_line, "# latitude_deg: 48.14\n# longitude_deg: 11.58"), encoding="utf-8")
    got, plain = _calibrated(no_date), _calibrated(no_place)
    assert any("no 'date'" in w and "NOT IGRF-anchored" in w for w in got["warnings"]), got["warnings"]
    assert got["igrf_anchored"] is False and plain["igrf_anchored"] is False
    for name in ("hard_iron", "soft_iron"):
        assert got["params"][name] == plain["params"][name]
