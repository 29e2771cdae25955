"""The recalibration due date moves earlier only for a significant drift trend.

A bench engineer reads "due earlier because of drift" as "the coefficients have moved,
beyond what the calibrations' own uncertainties explain". Calibrations that scatter
within their reported sigmas, with no trend, must leave the due date at the end of the
interval; a clear trend brings it forward, and the output says which parameter, how
steep, how sure and when it leaves its tolerance. Real SQLite files, built through the
store API; the commands read them as a user would.
"""

from __future__ import annotations

import json
import sqlite3
from datetime import UTC, datetime, timedelta

import numpy as np
import pytest
from db_testdata import accel_result, small_capture

from db import Store
from db.params import DAYS_PER_YEAR, DRIFT_MIN_CALIBRATIONS, DRIFT_SIGNIFICANCE, linear_trend, trend_verdict
from tests.station_run import run_main as run

T0 = datetime(2025, 1, 6, tzinfo=UTC)
SIGMA_B_MPS2 = 0.01  # each calibration's reported 1-sigma of B
SIGMA_M = 0.001  # and of each element of M
TOLERANCES = {"B": 0.02, "M": 0.003}  # a change from the value in use that fails a result
INTERVAL_D = 365
DAYS = [0, 45, 90, 135]  # four calibrations a season apart: commissioning and the first checks


def _iso(dt: datetime) -> str:
    return dt.strftime("%Y-%m-%dT%H:%M:%SZ")


def _save(store, device, days, rng, rate_B0_per_year=0.0):
    """Calibrations at T0 + days: B and M scatter as N(0, their reported sigma) about a fixed
    truth, plus (optionally) a linear trend of B[0]."""
    meta, cols = small_capture(device=device)
    for d in days:
        B = [0.1, -0.2, 0.3] + rng.normal(0.0, SIGMA_B_MPS2, 3)
        B[0] += rate_B0_per_year * d / DAYS_PER_YEAR
        M = np.eye(3) + rng.normal(0.0, SIGMA_M, (3, 3))
        store.save_calibration(
            accel_result(device=device, B=B, M=M, sigma_B=SIGMA_B_MPS2, sigma_M=SIGMA_M),
            meta=meta,
            columns=cols,
            allow_duplicate=True,
            time=_iso(T0 + timedelta(days=d)),
        )


def test_scatter_within_sigmas_keeps_the_interval(db, capsys):
    """No trend: the noise of four close calibrations gives apparent rates of ~0.04 m/s² a
    year, twice the tolerance; none is significant, so the due date is last + interval."""
    last = T0 + timedelta(days=DAYS[-1])
    with Store(db) as s:
        s.add_device("QUIET", interval_days=INTERVAL_D, tolerances=TOLERANCES)
        _save(s, "QUIET", DAYS, np.random.default_rng(400101))
        trends = s.drift("QUIET")
        # the defect's setting: an apparent rate that would leave the tolerance before the interval ends
        assert any(t["tolerance"] / abs(t["rate_per_year"]) < INTERVAL_D / DAYS_PER_YEAR for t in trends)
        assert not any(t["significant"] for t in trends)
        assert all(t["leaves_tolerance"] is None for t in trends)
    want = _iso(last + timedelta(days=INTERVAL_D))
    code, out, _ = run(capsys, "due", "--within", "400", "--now", _iso(last), "--json", "--db", db)
    [e] = json.loads(out)
    assert code == 1 and e["due"] == want
    [r] = e["reasons"]
    assert r["kind"] == "interval" and r["param"] is None
    assert "no significant drift over 4 calibrations" in r["text"]
    # nothing due before the interval ends, however steep the noise looked
    code, out, _ = run(capsys, "due", "--now", _iso(last + timedelta(days=INTERVAL_D - 1)), "--db", db)
    assert code == 0 and out == "nothing due\n"
    # station drift says the same: a sigma count per trend and no tolerance date
    code, out, _ = run(capsys, "drift", "QUIET", "--param", "B", "--no-plot", "--db", db)
    assert code == 0 and "SIGNIF" in out
    rows = [line for line in out.splitlines() if line.startswith("accel-tabletop")]
    assert len(rows) == 3 and all(line.rstrip().endswith("-") for line in rows), out


def test_clear_trend_brings_the_due_date_forward_and_says_why(db, capsys):
    """B[0] moves 0.25 m/s² a year (about 7 sigma of the rate over these four calibrations):
    it leaves its 0.02 tolerance about a month after the last one."""
    last = T0 + timedelta(days=DAYS[-1])
    with Store(db) as s:
        s.add_device("DRIFTY", interval_days=INTERVAL_D, tolerances=TOLERANCES)
        _save(s, "DRIFTY", DAYS, np.random.default_rng(400102), rate_B0_per_year=0.25)
        [t] = s.drift("DRIFTY", param="B[0]")
        assert t["significant"] and t["rate_per_year"] / t["rate_sigma_per_year"] > DRIFT_SIGNIFICANCE
        leaves = t["leaves_tolerance"]
    assert leaves is not None and _iso(last) < leaves < _iso(last + timedelta(days=60))
    code, out, _ = run(capsys, "due", "--within", "400", "--now", _iso(last), "--json", "--db", db)
    [e] = json.loads(out)
    assert code == 1 and e["due"] == leaves
    [r] = e["reasons"]
    assert r["kind"] == "drift" and r["param"] == "B[0]"
    assert "drift of B[0] (+0.2" in r["text"] and "σ over 4 calibrations" in r["text"]
    assert f"leaves its tolerance 0.02 on {leaves[:10]}" in r["text"]
    code, out, _ = run(capsys, "due", "--within", "400", "--now", _iso(last), "--db", db)
    assert out.startswith("DRIFTY: due in ") and "drift of B[0]" in out


def test_two_calibrations_are_not_enough_to_judge_a_trend(db, capsys):
    """Two calibrations 20 sigma apart: a change, but a trend needs the scatter about it
    checked against the sigmas, which takes a third calibration."""
    with Store(db) as s:
        s.add_device("PAIR", interval_days=INTERVAL_D, tolerances={"B": 0.02})
        meta, cols = small_capture(device="PAIR")
        for k, d in enumerate((0, 30)):
            s.save_calibration(
                accel_result(device="PAIR", B=(0.1 + 0.2 * k, -0.2, 0.3)),
                meta=meta,
                columns=cols,
                allow_duplicate=True,
                time=_iso(T0 + timedelta(days=d)),
            )
        [t] = s.drift("PAIR", param="B[0]")
        assert t["rate_per_year"] > 0 and not t["significant"] and t["leaves_tolerance"] is None
    last = T0 + timedelta(days=30)
    code, out, _ = run(capsys, "due", "--within", "400", "--now", _iso(last), "--json", "--db", db)
    [e] = json.loads(out)
    assert e["due"] == _iso(last + timedelta(days=INTERVAL_D))
    assert f"drift needs {DRIFT_MIN_CALIBRATIONS} accepted calibrations, has 2" in e["reasons"][0]["text"]


def test_no_tolerance_no_drift_date(db, capsys):
    with Store(db) as s:
        s.add_device("NOTOL", interval_days=INTERVAL_D)
        _save(s, "NOTOL", DAYS, np.random.default_rng(400103), rate_B0_per_year=5.0)
    last = T0 + timedelta(days=DAYS[-1])
    code, out, _ = run(capsys, "due", "--within", "400", "--now", _iso(last), "--json", "--db", db)
    [e] = json.loads(out)
    assert e["due"] == _iso(last + timedelta(days=INTERVAL_D))
    assert "no tolerances set" in e["reasons"][0]["text"]


def test_false_alarms_and_detection_of_the_verdict():
    """The verdict on many no-trend series (weighted, honest sigmas) and unweighted ones
    (no sigmas: Student's t on the scatter): the share called significant stays near the
    two-sided 3-sigma rate (0.27 %); a trend of 6 sigma is found nearly always."""
    rng = np.random.default_rng(400104)
    t_years = [d / DAYS_PER_YEAR for d in DAYS]
    x = np.array(t_years)
    rate_sigma = SIGMA_B_MPS2 / np.sqrt(((x - x.mean()) ** 2).sum())
    n = 4000
    null_w = null_u = found = 0
    for _ in range(n):
        y = list(rng.normal(0.0, SIGMA_B_MPS2, len(DAYS)))
        null_w += trend_verdict(linear_trend(t_years, y, [SIGMA_B_MPS2] * len(DAYS)))["significant"]
        null_u += trend_verdict(linear_trend(t_years, y, [None] * len(DAYS)))["significant"]
        z = [yi + 6 * rate_sigma * ti for yi, ti in zip(y, t_years)]
        found += trend_verdict(linear_trend(t_years, z, [SIGMA_B_MPS2] * len(DAYS)))["significant"]
    # 0.27 % of 4000 = 10.8; Poisson 3-sigma above it: 21
    assert null_w <= 21 and null_u <= 21, (null_w, null_u)
    assert found >= 0.95 * n  # 6 sigma against a 3-sigma threshold: P(miss) = P(z < -3) = 0.13 %, Birge widening aside


def test_verdict_reasons():
    few = trend_verdict(linear_trend([0.0, 1.0], [0.0, 1.0], [0.01, 0.01]))
    assert not few["significant"] and few["why"] == f"2 calibrations ({DRIFT_MIN_CALIBRATIONS} needed)"
    flat = trend_verdict(linear_trend([0.0, 0.5, 1.0], [0.0, 0.01, 0.0], [0.01] * 3))
    assert not flat["significant"] and flat["sigmas"] == pytest.approx(0.0, abs=1e-12)
    steep = trend_verdict(linear_trend([0.0, 0.5, 1.0], [0.0, 0.5, 1.0], [0.01] * 3))
    assert steep["significant"] and steep["sigmas"] == pytest.approx(1.0 / (0.01 / np.sqrt(0.5)))
    none = trend_verdict(linear_trend([0.0, 0.0, 0.0], [0.0, 0.5, 1.0], [0.01] * 3))
    assert not none["significant"] and none["sigmas"] is None


def test_a_database_scheduled_by_the_old_rule_is_rescheduled_on_opening(db):
    """A database whose schedule still has an insignificant drift date (the rule before this
    migration) gets the interval date when opened, and `verify` stays clean; a schedule row
    edited by hand is left as it is, so `verify` still reports it."""
    from db.schema import MIGRATION_NAMES

    last = T0 + timedelta(days=DAYS[-1])
    with Store(db) as s:
        old = {}
        for device in ("OLD", "EDITED"):
            s.add_device(device, interval_days=INTERVAL_D, tolerances=TOLERANCES)
            _save(s, device, DAYS, np.random.default_rng(400101))
            old[device] = s._schedule_row(s.conn, device, "accel-tabletop", significant_only=False)
            assert old[device][5] is not None and old[device][8] < _iso(last + timedelta(days=INTERVAL_D))
    raw = sqlite3.connect(db)
    with raw:
        raw.execute(
            "UPDATE schedule SET interval_due = ?, drift_due = ?, drift_param = ?, drift_rate_per_year = ?, due = ? "
            "WHERE device_id = 'OLD'",
            old["OLD"][4:9],
        )
        raw.execute("UPDATE schedule SET due = '2030-01-01T00:00:00Z' WHERE device_id = 'EDITED'")
        raw.execute("ALTER TABLE schedule DROP COLUMN reason")  # the table as it was before the migration
        raw.execute("DELETE FROM _sqlite_migrations WHERE name = ?", [MIGRATION_NAMES[-1]])
    raw.close()
    with Store(db) as s:
        rows = {r["device_id"]: r for r in s._query("SELECT device_id, due, reason FROM schedule")}
        assert rows["OLD"]["due"] == _iso(last + timedelta(days=INTERVAL_D))
        assert "no significant drift over 4 calibrations" in rows["OLD"]["reason"]
        assert rows["EDITED"]["due"] == "2030-01-01T00:00:00Z" and rows["EDITED"]["reason"] is None
        problems = s.verify()
        assert [(p["kind"], p["device_id"]) for p in problems] == [("schedule changed", "EDITED")]


def test_due_on_an_80_column_terminal_wraps_its_reasons(db):
    """A drift reason is one sentence of about 150 columns, which an 80-column terminal broke
    mid-word; on a terminal it wraps between words at its width, indented, and into a pipe it
    stays one line (the test above reads it so)."""
    import os

    from tests.test_terminal_safety import _pty_run

    last = T0 + timedelta(days=DAYS[-1])
    with Store(db) as s:
        s.add_device("DRIFTY", interval_days=INTERVAL_D, tolerances=TOLERANCES)
        _save(s, "DRIFTY", DAYS, np.random.default_rng(400102), rate_B0_per_year=0.25)
    env = {**os.environ, "COLUMNS": "80", "LINES": "24"}
    rc, out = _pty_run("due", "--within", "400", "--now", _iso(last), "--db", db, env=env)
    lines = out.decode("utf-8").splitlines()
    assert rc == 1 and lines[0].startswith("DRIFTY: due in "), lines
    assert max(len(x) for x in lines) <= 80, max(lines, key=len)
    reason = " ".join(x.strip() for x in lines[1:])
    assert "drift of B[0] (+0.2" in reason and "leaves its tolerance 0.02 on" in reason, reason
