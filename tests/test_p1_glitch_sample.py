"""One glitch sample (a bus error, a stray byte: 1e4 V from a 0-5 V accelerometer) inside a
labelled P1 hold. The hold's mean took it whole: `station calibrate` moved B by 5 m/s^2 and its
residual from 0.0002 to 17 m/s^2 RMS, exit 0 and no warning (the hold's standard deviation grew
with the glitch, so the reduced chi-square still read 1.3). The sample is left out of its hold
and the warning names its line; the result is the clean capture's.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.station_run import run_station


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    path = tmp_path_factory.mktemp("p1") / "clean.csv"
    res = run_station("simulate", "--procedure", "accel-tabletop", "--out", path, "--seed", "6",
                      "--option", "hold_s=4", "--option", "move_s=1")  # fmt: skip
    assert res.returncode == 0, res.stderr
    return path


def _calibrate(path) -> dict:
    res = run_station("calibrate", path, "--json")
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout)


@pytest.mark.parametrize("value", ["1e4", "-40", "1e15"])
def test_a_glitch_sample_in_a_labelled_hold_is_left_out_and_named(tmp_path, clean, value):
    lines = clean.read_text().splitlines()
    header = next(i for i, line in enumerate(lines) if line.startswith("t,"))
    names = lines[header].split(",")
    at = header + 150  # inside the first hold
    fields = lines[at].split(",")
    assert fields[names.index("position")], "the row must be inside a labelled hold"
    fields[names.index("ax")] = value
    lines[at] = ",".join(fields)
    glitch = tmp_path / "glitch.csv"
    glitch.write_text("\n".join(lines) + "\n")

    before, after = _calibrate(clean), _calibrate(glitch)
    np.testing.assert_allclose(after["params"]["B"], before["params"]["B"], atol=1e-3)  # m/s^2: one of ~400 samples
    assert after["residual_rms"] < 2 * before["residual_rms"]
    said = [w for w in after["warnings"] if "left out of its hold" in w]
    assert len(said) == 1 and f"line {at + 1}: ax {float(value):g}" in said[0], after["warnings"]
    assert not any("left out of" in w for w in before["warnings"])
