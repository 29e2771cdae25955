"""The command line's text for a person says what the screens say: P4's drift and rates in
°/h, the compass's soft iron as a ratio (mag unit per mag unit), each with its unit; the
JSON keeps the stored units (calibrate.md: rad/s, nT per mag unit). Real CLI, real SQLite."""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest
from station_run import assert_one_line_refusal, run_station

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
    # "value ± sigma" entries; below the diagonal "0 ± —": fixed by the triangular form, not estimated
    entries = [line.strip().strip("[]").split(", ") for line in lines[i + 1 : i + 4]]
    rows = [[_numbers(e.split(" ± ")[0])[0] for e in row] for row in entries]
    W = np.asarray(js["params"]["soft_iron"]) / 1000.0  # nT per uT → uT per uT
    assert np.allclose(rows, W, rtol=1e-5, atol=1e-9)
    sigmas = [[e.split(" ± ")[1] for e in row] for row in entries]
    assert [sigmas[1][0], sigmas[2][0], sigmas[2][1]] == ["—"] * 3 and "—" not in sigmas[0]
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

    # typed in °/h as the screens show it; stored in rad/s
    assert run_station("devices", "--db", db, "add", "G1", "--limit", "drift=-206.265:206.265").returncode == 0
    assert run_station("devices", "--db", db, "add", "G1", "--tolerance", "drift=2.06265").returncode == 0
    show = run_station("devices", "--db", db, "show", "G1").stdout
    # as --limit takes it (the screens' unit, said), and the stored value with its unit
    assert "limits: drift=-206.265:206.265 °/h (stored -0.001:0.001 rad/s)" in show
    assert "tolerances: drift=2.06265 °/h (stored 1e-05 rad/s)" in show

    table = run_station("drift", "G1", "--no-plot", "--db", db).stdout.splitlines()
    head = table[1].split()
    row = next(line.split() for line in table if line.split()[1:2] == ["drift[1]"])
    assert head[:5] == ["PROCEDURE", "PARAM", "UNIT", "N", "IN_USE"] and row[2] == "°/h"
    assert float(row[4]) == pytest.approx(js["params"]["drift"][1] / DEG_H, rel=1e-5)
    assert float(row[head.index("TOLERANCE")]) == pytest.approx(2.06265, rel=1e-5)


def test_diagnose_text_p4_residuals_in_deg_per_hour_json_in_rad_per_s(tmp_path):
    path = tmp_path / "p4.csv"
    r = run_station(
        "simulate", "--procedure", "gyro-drift", "--seed", 402002, "--option", "duration_s=60", "--out", path
    )
    assert r.returncode == 0, r.stderr
    text = run_station("diagnose", path, "--no-plots").stdout
    js = json.loads(run_station("diagnose", path, "--json").stdout)
    res = re.search(r"baseline .*\n +residual (\S+) (\S+) RMS of \S+ s block means, held-out (\S+) (\S+) RMS", text)
    assert res.group(2) == res.group(4) == "°/h", text
    assert re.search(r"time_drift +ΔBIC +\S+ +held-out RMS \S+ °/h", text), text
    assert float(res.group(1)) == pytest.approx(js["baseline"]["residual_rms"] / DEG_H, rel=1e-3)
    assert float(res.group(3)) == pytest.approx(js["baseline"]["cv_rms"] / DEG_H, rel=1e-3)
    assert "per time block [°/h]" in text and "rad/s" not in text


def _device_json(db, device):
    r = run_station("devices", "show", device, "--json", "--db", db)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


def test_limits_and_tolerances_typed_in_the_units_printed(saved, tmp_path):
    """--limit/--tolerance take what the text and screens print (P4 drift in °/h, the
    compass's soft iron as a ratio); the database keeps rad/s and nT per uT; a FAIL names the
    limit as it was typed."""
    db, out = saved
    # a new unit, no calibration yet: the drift's unit is P4's all the same
    new = tmp_path / "new.db"
    r = run_station("devices", "add", "G9", "--limit", "drift=-20:", "--tolerance", "drift=2", "--db", new)
    assert r.returncode == 0, r.stderr
    d = _device_json(new, "G9")
    assert d["limits"]["drift"] == [pytest.approx(-20 * DEG_H, rel=1e-12), None]
    assert d["tolerances"]["drift"] == pytest.approx(2 * DEG_H, rel=1e-12)

    # the calibration in use, read in °/h: a limit half its largest drift fails it
    drift_deg_h = np.asarray(out["gyro-drift"][1]["params"]["drift"]) / DEG_H
    k = int(np.argmax(abs(drift_deg_h)))
    half = round(abs(drift_deg_h[k]) / 2, 3)
    assert half > 0.05, drift_deg_h  # a limit the old rad/s reading would pass by far
    assert run_station("devices", "add", "G1", "--limit", f"drift[{k}]=-{half}:{half}", "--db", db).returncode == 0
    assert _device_json(db, "G1")["limits"][f"drift[{k}]"] == pytest.approx([-half * DEG_H, half * DEG_H])
    r = run_station("calibrate", db.parent / "gyro-drift.csv", "--device", "G1", "--save", "--db", db)
    assert r.returncode == 1, (r.stdout, r.stderr)
    assert f"drift[{k}] = {drift_deg_h[k]:.6g} °/h outside its limits {-half:g} … {half:g} °/h" in r.stderr
    assert run_station("devices", "add", "G1", "--limit", f"drift[{k}]=", "--db", db).returncode == 0

    # the residual in P4's unit, told by G1's calibration
    assert run_station("devices", "add", "G1", "--tolerance", "residual_rms=30", "--db", db).returncode == 0
    assert _device_json(db, "G1")["tolerances"]["residual_rms"] == pytest.approx(30 * DEG_H, rel=1e-12)
    assert "residual_rms=30 °/h (stored " in run_station("devices", "show", "G1", "--db", db).stdout

    # the compass's soft iron as a ratio, stored per the capture's unit (uT: nT per uT)
    assert out["compass"][1]["mag_unit"] == "uT"
    r = run_station("devices", "add", "M1", "--limit", "soft_iron[0][0]=0.9:1.1", "--db", db)
    assert r.returncode == 0, r.stderr
    assert _device_json(db, "M1")["limits"]["soft_iron[0][0]"] == pytest.approx([900.0, 1100.0, "nT per uT"])
    show = run_station("devices", "show", "M1", "--db", db).stdout
    assert "soft_iron[0][0]=0.9:1.1 uT/uT (stored 900:1100 nT per uT)" in show


@pytest.mark.parametrize(
    "args,needles",
    [
        (["--limit", "drift=abc"], ["--limit 'drift=abc'", "LOW:HIGH", "drift is in °/h"]),
        (["--limit", "drift=5:-5"], ["--limit 'drift=5:-5'", "LOW <= HIGH", "drift is in °/h"]),
        (["--tolerance", "drift=-1"], ["--tolerance 'drift=-1'", "positive", "drift is in °/h"]),
        (["--tolerance", "drift=inf"], ["--tolerance 'drift=inf'", "positive", "°/h"]),
        (["--tolerance", "residual_rms=5"], ["residual_rms", "no calibration yet"]),
        (["--limit", "B=0.5", "--model", "X"], ["--limit 'B=0.5'", "LOW:HIGH"]),
    ],
)
def test_bad_limit_or_tolerance_one_line_nothing_written(tmp_path, args, needles):
    db = tmp_path / "none.db"
    assert_one_line_refusal(run_station("devices", "add", "G9", *args, "--db", db), *needles)
    assert not db.exists()  # refused before the database is made


def _device_a1_with_a_p1_calibration(tmp_path, capsys) -> str:
    """A database whose device A1 has one saved P1 calibration (B, M); its path."""
    from station.cli import main

    db = str(tmp_path / "s.db")
    cap = tmp_path / "p1.csv"
    assert main(["simulate", "--procedure", "accel-tabletop", "--out", str(cap), "--seed", "400003"]) == 0
    assert main(["calibrate", str(cap), "--save", "--device", "A1", "--db", db]) == 0
    capsys.readouterr()
    return db


def test_a_limit_that_limits_nothing_of_the_device_is_refused(tmp_path, capsys):
    """`--limit dirft=-10:10` (a typo) or `B[9]=...` on a device whose calibrations say what
    it has was stored and never checked: every later calibration passed it by. Refused in one
    line naming what the device has; nothing stored. A limit for another procedure's first
    calibration is still taken; on a device with no calibration yet, any procedure's parameter
    is (a name no procedure's result holds is refused there too: see
    test_a_typo_on_a_device_with_no_calibration_yet_is_refused)."""
    from db import Store
    from station.cli import main

    db = _device_a1_with_a_p1_calibration(tmp_path, capsys)
    for item, says in [
        ("dirft=-10:10", "no parameter 'dirft' in this device's calibrations (B, M)"),
        ("B[9]=-1:1", "B of this device is B[0] … B[2]: no B[9]"),
        ("M[3][0]=0:1", "M of this device is M[0][0] … M[2][2]: no M[3][0]"),
    ]:
        code = main(["devices", "add", "A1", "--limit", item, "--db", db])
        out, err = capsys.readouterr()
        assert code == 2 and out == "" and err.count("\n") == 1, err
        assert f"--limit {item!r}: {says}" in err
    assert Store(db).get_device("A1")["limits"] == {}
    for item in ("B[2]=-25:25", "M=-20:20", "residual_rms=:0.01", "drift=-10:10"):  # drift: P4's, not yet run
        assert main(["devices", "add", "A1", "--limit", item, "--db", db]) == 0, capsys.readouterr().err
    assert sorted(Store(db).get_device("A1")["limits"]) == ["B[2]", "M", "drift", "residual_rms"]
    assert main(["devices", "add", "NEW", "--limit", "drift=-10:10", "--db", db]) == 0


@pytest.mark.parametrize("option", ["--limit", "--tolerance"])
def test_a_typo_on_a_device_with_no_calibration_yet_is_refused(tmp_path, capsys, option):
    """A device is registered with its limits and tolerances before its first calibration (the
    README's example), and there `--tolerance dirft=10`, `--limit nope=0:1` or `--limit
    'M[0][3]=0.9:1.1'` were stored and never checked: the first calibrations passed them by, the
    engineer believing the unit judged. Every procedure's result holds a known set of names
    (calibrate.md; the modules' PARAM_SHAPES): a name none holds is refused in one line, as on
    a calibrated device; every name some procedure holds is still taken."""
    from db import Store
    from station.cli import main

    db = str(tmp_path / "s.db")
    assert main(["devices", "add", "NEW", "--db", db]) == 0
    capsys.readouterr()
    value = "=0.1" if option == "--tolerance" else "=0:1"
    for name, says in [
        ("dirft", "no parameter 'dirft' in any procedure's results"),
        ("M[0][3]", "M is M[0][0] … M[2][2]: no M[0][3]"),
        ("gamma[6]", "gamma is gamma[0] … gamma[5]: no gamma[6]"),
        ("beam4.dK", "no parameter 'beam4.dK'"),
    ]:
        code = main(["devices", "add", "NEW", option, name + value, "--db", db])
        out, err = capsys.readouterr()
        assert code == 2 and out == "" and err.count("\n") == 1, err
        assert says in err, err
    dev = Store(db).get_device("NEW")
    assert dev["limits"] == {} and dev["tolerances"] in ({}, None), dev
    good = ["B[2]", "M", "S[0]", "gamma[5]", "drift", "earth_rate_body[1]", "pitch_deg", "hard_iron", "beam2.dK",
            "reference.total_nT", "condition_number"]  # fmt: skip
    for name in good:
        assert main(["devices", "add", "NEW", option, name + value, "--db", db]) == 0, capsys.readouterr().err
    key = "limits" if option == "--limit" else "tolerances"
    assert sorted(Store(db).get_device("NEW")[key]) == sorted(good)


def test_a_tolerance_that_names_nothing_of_the_device_is_refused_as_a_limit_is(tmp_path, capsys):
    """`--tolerance dirft=10` (a typo) was stored and never checked, so the drift trend that
    should have scheduled the device early never could; the same typo in --limit is refused.
    The tolerance is refused with the limit's words; the right names are still taken."""
    from db import Store
    from station.cli import main

    db = _device_a1_with_a_p1_calibration(tmp_path, capsys)
    for item, says in [
        ("dirft=10", "no parameter 'dirft' in this device's calibrations (B, M)"),
        ("B[9]=0.1", "B of this device is B[0] … B[2]: no B[9]"),
    ]:
        code = main(["devices", "add", "A1", "--tolerance", item, "--db", db])
        out, err = capsys.readouterr()
        assert code == 2 and out == "" and err.count("\n") == 1, err
        assert f"--tolerance {item!r}: {says}" in err
    assert Store(db).get_device("A1")["tolerances"] == {}
    for item in ("B[2]=0.1", "M=0.01", "drift=10"):  # drift: P4's, not yet run
        assert main(["devices", "add", "A1", "--tolerance", item, "--db", db]) == 0, capsys.readouterr().err
    assert sorted(Store(db).get_device("A1")["tolerances"]) == ["B[2]", "M", "drift"]


def test_a_soft_iron_limit_keeps_its_unit_whatever_the_captures_unit(tmp_path):
    """The compass's soft iron is typed as a ratio and stored per the capture's mag_unit. A limit
    set before the device's first compass calibration was refused (no unit to convert to), and
    one stored unitless was read in whatever unit a later capture had: 0.9:1.1 typed as a ratio
    read as nT per uT failed every compass calibration; 500:2000 nT per uT read as nT per gauss
    too. The limit now keeps its unit (a ratio, or nT per uT) and each result reads it in its own."""
    from station.capture import Capture, read_capture, write_capture

    db = tmp_path / "s.db"
    cap = tmp_path / "c.csv"
    assert run_station("simulate", "--procedure", "compass", "--out", cap, "--seed", "7").returncode == 0
    r = run_station("devices", "add", "M9", "--limit", "soft_iron[0][0]=0.5:2", "--db", db)
    assert r.returncode == 0, r.stderr  # before any compass calibration: typed as a ratio, kept so
    assert _device_json(db, "M9")["limits"]["soft_iron[0][0]"] == [0.5, 2.0, "ratio"]
    r = run_station("calibrate", cap, "--device", "M9", "--save", "--db", db)
    assert r.returncode == 0 and "PASS" in r.stdout, (r.stdout, r.stderr)
    assert "soft_iron[0][0]=0.5:2 uT/uT (stored 0.5:2 ratio)" in run_station("devices", "show", "M9", "--db", db).stdout
    r = run_station("devices", "add", "M9", "--limit", "soft_iron[1][1]=0.5:2", "--db", db)
    assert r.returncode == 0, r.stderr  # after one: in that calibration's stored unit, said
    assert _device_json(db, "M9")["limits"]["soft_iron[1][1]"] == pytest.approx([500.0, 2000.0, "nT per uT"])
    # the same unit in gauss: 1 gauss = 100 uT, so the stored soft iron is 100x, the ratio the same
    c = read_capture(cap)
    gauss = tmp_path / "gauss.csv"
    cols = {k: v / 100.0 if k in ("mx", "my", "mz") else v for k, v in c.columns.items()}
    write_capture(gauss, Capture(dict(c.meta, mag_unit="gauss"), cols))
    r = run_station("calibrate", gauss, "--device", "M9", "--save", "--db", db)
    assert r.returncode == 0 and "PASS" in r.stdout, (r.stdout, r.stderr)
    # and a limit the soft iron is outside fails in the unit it was typed in
    assert run_station("devices", "add", "M9", "--limit", "soft_iron[0][0]=0.5:0.6", "--db", db).returncode == 0
    r = run_station("calibrate", gauss, "--device", "M9", "--save", "--db", db)
    assert r.returncode == 1, (r.stdout, r.stderr)
    assert re.search(
        r"soft_iron\[0\]\[0\] = [01]\.\d+ gauss/gauss outside its limits 0\.5 … 0\.6 gauss/gauss", r.stderr
    )
    # a unit no result converts to (a raw one) is not passed unread: the result fails, saying why
    from db import Store

    Store(str(db)).add_device("M9", limits={"soft_iron[0][0]": [500.0, 2000.0, "nT per counts"]})
    r = run_station("calibrate", cap, "--device", "M9", "--save", "--db", db)
    assert r.returncode == 1
    assert (
        "soft_iron[0][0]: its limit is in nT per counts, which does not convert to this result's nT per uT" in r.stderr
    )


def test_p1_results_table_gives_the_residuals_calibrate_gives(tmp_path):
    """The Results screen's P1 table and `station calibrate` show the same per-position
    residuals, whose RMS is the summary's residual_rms. The table recomputed |B + M V| − g
    with the returned B, M, which carry the rotation's second-order debiasing: every row was
    about +1e-4 m/s² off the fit's residual (all positive; RMS 1.2e-4 against 5.5e-5)."""
    from station.capture import read_capture
    from station.procedures.review import residual_table

    path = tmp_path / "p1.capture.csv"
    assert run_station("simulate", "--procedure", "accel-tabletop", "--out", str(path), "--seed", "0").returncode == 0
    res = run_station("calibrate", str(path), "--json")
    assert res.returncode == 0, res.stderr
    result = json.loads(res.stdout)
    _, rows = residual_table(read_capture(str(path)), result)
    table = np.array([float(r[2]) for r in rows])
    fit = np.array([p["residual_mps2"] for p in result["positions"]])
    assert [r[0] for r in rows] == [p["label"] for p in result["positions"]]
    np.testing.assert_allclose(table, fit, atol=1e-7)  # the table's 7 decimals
    assert math.isclose(math.sqrt(np.mean(table**2)), result["residual_rms"], rel_tol=1e-2)
