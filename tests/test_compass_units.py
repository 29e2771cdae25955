"""The compass's text names the unit of every figure and puts the residual (nT, the calibrated
field's unit) beside the hard iron in one unit: the hard iron is in the capture's own mag_unit
(uT, gauss, counts), as the JSON contract keeps it. The text said `residual 149 nT` beside a
hard iron in uT, and diagnose's hard-iron step `dh = [1.82, ...]` with no unit at all."""

from __future__ import annotations

import json
import re

import pytest
from station_run import run_station

from station.capture import read_capture, write_capture

NT_PER = {"uT": 1e3, "gauss": 1e5}


@pytest.fixture(scope="module")
def captures(tmp_path_factory):
    """One simulated compass run with a hard-iron step (2 uT), as written (uT), and the same
    samples in gauss and in counts (a unit with no physical factor)."""
    tmp = tmp_path_factory.mktemp("units")
    path = tmp / "uT.csv"
    r = run_station(
        "simulate", "--procedure", "compass", "--seed", 5, "--effect", "time_varying_hard_iron=2", "--out", path
    )
    assert r.returncode == 0, r.stderr
    assert read_capture(path).meta["mag_unit"] == "uT"
    out = {"uT": path}
    for unit, k in (("gauss", 1e-2), ("counts", 6.7)):
        cap = read_capture(path)
        for c in ("mx", "my", "mz"):
            cap.columns[c] = cap.columns[c] * k
        cap.meta["mag_unit"] = unit
        out[unit] = tmp / f"{unit}.csv"
        write_capture(out[unit], cap)
    return out


def _floats(text: str) -> list[float]:
    return [float(x) for x in re.findall(r"[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?", text)]


@pytest.mark.parametrize("unit", ["uT", "gauss", "counts"])
def test_calibrate_says_the_residual_in_the_hard_irons_unit_too(captures, unit):
    text = run_station("calibrate", captures[unit])
    js = run_station("calibrate", captures[unit], "--json")
    assert text.returncode == js.returncode == 0, text.stderr + js.stderr
    result = json.loads(js.stdout)
    assert result["mag_unit"] == unit and "hard_iron" in result["params"]  # the contract, as it was
    assert f"hard_iron [{unit}]:" in text.stdout
    line = next(x for x in text.stdout.splitlines() if x.startswith("residual "))
    res = result["residual_rms"]
    if unit in NT_PER:
        m = re.match(rf"residual\s+(\S+) nT RMS = (\S+) {unit};", line)
        assert m, line
        assert float(m.group(1)) == pytest.approx(res, rel=1e-3)
        assert float(m.group(2)) == pytest.approx(res / NT_PER[unit], rel=1e-3)
    else:  # no physical factor: through the calibration's own gain (nT per count), said as such
        m = re.match(r"residual\s+(\S+) nT RMS ≈ (\S+) counts \(through the soft iron's mean gain (\S+) nT per", line)
        assert m, line
        assert float(m.group(2)) * float(m.group(3)) == pytest.approx(res, rel=1e-2)


def test_diagnose_names_the_hard_iron_steps_unit_and_says_it_in_nT_beside_the_residuals(captures):
    """The same physical step reads the same in nT whatever unit the capture is in."""
    in_nT = {}
    for unit in ("uT", "gauss", "counts"):
        text = run_station("diagnose", captures[unit], "--no-plots")
        js = run_station("diagnose", captures[unit], "--json")
        assert text.returncode == js.returncode == 0, text.stderr + js.stderr
        result = json.loads(js.stdout)
        assert result["verdict"][0] == "time_varying_hard_iron"
        dh = next(e for e in result["effects"] if e["name"] == "time_varying_hard_iron")["params"]["dh"]
        assert result["units"]["residuals"] == "nT" and result["units"]["dh"] == unit
        assert re.search(r"residual \S+ nT RMS, held-out \S+ nT RMS", text.stdout)
        line = next(x for x in text.stdout.splitlines() if x.strip().startswith("dh = "))
        value, rest = line.split(" ± ", 1)
        assert _floats(value) == pytest.approx(dh, rel=1e-6, abs=1e-8)
        if unit in NT_PER:
            m = re.fullmatch(rf"\[[^]]+\] {unit} \(= (\[[^]]+\]) ± \[[^]]+\] nT\)", rest)
            assert m, line
            in_nT[unit] = _floats(m.group(1))
            assert in_nT[unit] == pytest.approx([x * NT_PER[unit] for x in dh], rel=1e-5)
        else:
            assert re.fullmatch(r"\[[^]]+\] counts", rest), line
        t_on = next(x for x in text.stdout.splitlines() if x.strip().startswith("t_on_s = "))
        assert t_on.strip().endswith("± — s"), t_on  # found by a scan: its σ is not estimated
    assert in_nT["uT"] == pytest.approx(in_nT["gauss"], rel=1e-4)
