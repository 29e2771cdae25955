"""The command line's text for a person says what the screens say: P4's drift and rates in
°/h, the compass's soft iron as a ratio (mag unit per mag unit), each with its unit; the
JSON keeps the stored units (calibrate.md: rad/s, nT per mag unit). Real CLI, real SQLite."""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest
from station_run import run_station

DEG_H = math.pi / 648000.0  # 1 °/h in rad/s


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("units")
    db = tmp / "station.db"
    out = {}
    for proc, device, seed in (("gyro-drift", "G1", 402000), ("compass", "M1", 402001)):
        path = tmp / f"{proc}.csv"
        assert run_station("simulate", "--procedure", proc, "--seed", seed, "--out", path).returncode == 0
        text = run_station("calibrate", path, "--device", device)
        js = run_station("calibrate", path, "--device", device, "--json", "--save", "--db", db)
        assert text.returncode == 0 and js.returncode == 0, (text.stderr, js.stderr)
        out[proc] = (text.stdout, json.loads(js.stdout))
    return db, out


def _numbers(text: str) -> list[float]:
    return [float(x) for x in re.findall(r"[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?", text)]


def test_calibrate_text_p4_in_deg_per_hour_json_in_rad_per_s(saved):
    _, out = saved
    text, js = out["gyro-drift"]
    drift_line = next(line for line in text.splitlines() if line.startswith("drift "))
    assert drift_line.endswith(" °/h") and "rad/s" not in text.replace("(x forward, y up", "")
    shown = re.findall(r"([xyz]) ([-+]\d+\.\d+) ± (\S+)", drift_line)
    assert [a for a, _, _ in shown] == ["x", "y", "z"]
    for (_, v, s), want, sig in zip(shown, js["params"]["drift"], js["uncertainty"]["drift"]):
        assert float(v) == pytest.approx(want / DEG_H, abs=0.006)  # printed to 0.01 °/h
        assert float(s) == pytest.approx(sig / DEG_H, rel=0.06)  # two digits
    res = re.search(r"residual +(\S+) (\S+) RMS", text)
    assert res.group(2) == "°/h" and float(res.group(1)) == pytest.approx(js["residual_rms"] / DEG_H, rel=1e-3)
    # the JSON is the contract: rad/s, a MEMS gyro's drift well under 0.1 rad/s
    assert all(abs(x) < 0.1 for x in js["params"]["drift"])


def test_calibrate_text_compass_soft_iron_as_a_ratio(saved):
    _, out = saved
    text, js = out["compass"]
    assert js["mag_unit"] == "uT"
    lines = text.splitlines()
    i = next(k for k, line in enumerate(lines) if "soft_iron" in line)
    assert lines[i].strip() == "soft_iron [uT/uT]:"
    rows = [_numbers(line)[0::2] for line in lines[i + 1 : i + 4]]  # value ± sigma pairs
    W = np.asarray(js["params"]["soft_iron"]) / 1000.0  # nT per uT → uT per uT
    assert np.allclose(rows, W, rtol=1e-5, atol=1e-9)
    assert 0.8 < W[0][0] < 1.2  # a ratio near one, as the Results screen shows it
    assert "hard_iron [uT]:" in text
    assert text.count("saved ") <= 1  # the compass said 'saved calibration N' twice


def test_history_drift_and_devices_show_in_the_units_of_the_screens(saved, capsys):
    db, out = saved
    js = out["gyro-drift"][1]
    r = run_station("history", "G1", "--db", db)
    drift = next(line.strip() for line in r.stdout.splitlines() if line.strip().startswith("drift"))
    assert drift.startswith("drift [°/h]: ")
    values = _numbers(drift.split(":", 1)[1])[0::2]
    assert values == pytest.approx([v / DEG_H for v in js["params"]["drift"]], rel=1e-5)
    assert re.search(r"residual_rms \S+ °/h", r.stdout)
    m = run_station("history", "M1", "--db", db)
    assert "soft_iron [uT/uT]: " in m.stdout and "hard_iron [uT]: " in m.stdout
    # --json keeps the stored units
    rec = json.loads(run_station("history", "G1", "--json", "--db", db).stdout)[0]
    assert rec["params"]["drift"] == pytest.approx(js["params"]["drift"])

    assert run_station("devices", "--db", db, "add", "G1", "--limit", "drift=-0.001:0.001").returncode == 0
    assert run_station("devices", "--db", db, "add", "G1", "--tolerance", "drift=1e-5").returncode == 0
    show = run_station("devices", "--db", db, "show", "G1").stdout
    # as --limit takes it (stored unit, said), and as the screens show it
    assert "limits: drift=-0.001:0.001 rad/s (-206.265:206.265 °/h)" in show
    assert "tolerances: drift=1e-05 rad/s (2.06265 °/h)" in show

    table = run_station("drift", "G1", "--no-plot", "--db", db).stdout.splitlines()
    head = table[1].split()
    row = next(line.split() for line in table if line.split()[1:2] == ["drift[1]"])
    assert head[:5] == ["PROCEDURE", "PARAM", "UNIT", "N", "IN_USE"] and row[2] == "°/h"
    assert float(row[4]) == pytest.approx(js["params"]["drift"][1] / DEG_H, rel=1e-5)
    assert float(row[head.index("TOLERANCE")]) == pytest.approx(1e-5 / DEG_H, rel=1e-5)


def test_diagnose_text_p4_residuals_in_deg_per_hour_json_in_rad_per_s(tmp_path):
    path = tmp_path / "p4.csv"
    r = run_station(
        "simulate", "--procedure", "gyro-drift", "--seed", 402002, "--option", "duration_s=60", "--out", path
    )
    assert r.returncode == 0, r.stderr
    text = run_station("diagnose", path, "--no-plots").stdout
    js = json.loads(run_station("diagnose", path, "--json").stdout)
    res = re.search(r"baseline .*\n +residual (\S+) (\S+) RMS, held-out (\S+)", text)
    assert res.group(2) == "°/h", text
    assert float(res.group(1)) == pytest.approx(js["baseline"]["residual_rms"] / DEG_H, rel=1e-3)
    assert float(res.group(3)) == pytest.approx(js["baseline"]["cv_rms"] / DEG_H, rel=1e-3)
    assert "per time block [°/h]" in text and "rad/s" not in text
