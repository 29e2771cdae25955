"""Drift trends and recalibration reminders on devices with known synthetic drift."""

from __future__ import annotations

import math
from datetime import UTC, datetime, timedelta

import numpy as np
import pytest
from db_testdata import accel_result, small_capture

from db import Store
from db.params import DAYS_PER_YEAR, linear_trend

T0 = datetime(2022, 1, 1, tzinfo=UTC)


def _save_series(store, device, days, B0, rates, sigma, rng=None, accepted=None, procedure_result=accel_result):
    """Calibrations at T0 + days with B = B0 + rate * years (+ N(0, sigma) noise when rng is given)."""
    meta, cols = small_capture(device=device)
    ids = []
    for k, d in enumerate(days):
        years = d / DAYS_PER_YEAR
        B = [b + r * years for b, r in zip(B0, rates)]
        if rng is not None:
            B = [b + rng.normal(0.0, sigma) for b in B]
        when = (T0 + timedelta(days=d)).strftime("%Y-%m-%dT%H:%M:%SZ")
        ok = True if accepted is None else accepted[k]
        ids.append(
            store.save_calibration(
                procedure_result(device=device, B=B, sigma_B=sigma),
                meta=meta,
                columns=cols,
                allow_duplicate=True,
                time=when,
                accepted=ok,
            )
        )
    return ids


@pytest.fixture
def store(tmp_path):
    s = Store(str(tmp_path / "station.db"))
    yield s
    s.close()


def test_linear_trend_known_answers():
    # exact line: rate and intercept exact, sigma from the given sigmas: 1/sqrt(sum w (t - tm)^2)
    t = [0.0, 0.5, 1.0, 2.0]
    fit = linear_trend(t, [1.0 + 0.3 * x for x in t], [0.1] * 4)
    assert fit["rate"] == pytest.approx(0.3, abs=1e-12)
    assert fit["intercept"] == pytest.approx(1.0, abs=1e-12)
    tm = sum(t) / 4
    assert fit["rate_sigma"] == pytest.approx(0.1 / math.sqrt(sum((x - tm) ** 2 for x in t)), rel=1e-12)
    # unweighted without sigmas: rate sigma from the scatter (3 points: 1 dof)
    fit = linear_trend([0.0, 1.0, 2.0], [0.0, 1.1, 1.9], [None] * 3)
    assert fit["rate"] == pytest.approx(0.95)
    resid = [0.0 - 0.05, 1.1 - 1.0, 1.9 - 1.95]
    assert fit["rate_sigma"] == pytest.approx(math.sqrt(sum(r * r for r in resid) / 1 / 2.0))
    # scatter far above the sigmas widens the rate sigma (Birge ratio), never narrows it
    wide = linear_trend([0, 1, 2, 3], [0, 1, -1, 0], [0.01] * 4)
    assert wide["rate_sigma"] > 10 * 0.01 / math.sqrt(5)
    # fewer than two distinct times: no rate
    assert linear_trend([1.0, 1.0], [2.0, 3.0], [0.1, 0.1])["rate"] is None
    assert linear_trend([], [], [])["rate"] is None


def test_noise_free_drift_is_recovered_exactly(store):
    days = [0, 100, 250, 400, 800]
    _save_series(store, "D0", days, B0=(0.1, -0.2, 0.3), rates=(0.02, -0.05, 0.0), sigma=0.004)
    trends = {t["param"]: t for t in store.drift("D0", param="B")}
    assert set(trends) == {"B[0]", "B[1]", "B[2]"}
    assert trends["B[0]"]["rate_per_year"] == pytest.approx(0.02, abs=1e-12)
    assert trends["B[1]"]["rate_per_year"] == pytest.approx(-0.05, abs=1e-12)
    assert trends["B[2]"]["rate_per_year"] == pytest.approx(0.0, abs=1e-12)
    years = np.array(days) / DAYS_PER_YEAR
    expected_sigma = 0.004 / math.sqrt(((years - years.mean()) ** 2).sum())
    assert trends["B[0]"]["rate_sigma_per_year"] == pytest.approx(expected_sigma, rel=1e-9)
    assert trends["B[0]"]["n"] == 5 and trends["B[0]"]["value_in_use"] == pytest.approx(0.1 + 0.02 * years[-1])
    # names: every scalar of the result, selectable singly
    all_names = {t["param"] for t in store.drift("D0")}
    assert {"B[0]", "M[0][0]", "M[2][1]"} <= all_names and len(all_names) == 12
    assert [t["param"] for t in store.drift("D0", param="M[1][2]")] == ["M[1][2]"]


def test_noisy_drift_of_several_devices_within_sigma(store):
    rng = np.random.default_rng(2024)
    truth = {
        "A": (0.02, -0.01, 0.0),
        "B": (-0.05, 0.0, 0.03),
        "C": (0.0, 0.1, -0.02),
        "D": (0.004, 0.0, 0.0),
        "E": (-0.3, 0.2, 0.01),
    }
    sigma = 0.005
    pulls = []
    for device, rates in truth.items():
        days = sorted(rng.uniform(0, 3 * 365.25, 12))  # irregular times over three years
        _save_series(store, device, days, B0=(0.1, 0.2, 0.3), rates=rates, sigma=sigma, rng=rng)
        for t in store.drift(device, param="B"):
            i = int(t["param"][2])
            pulls.append((t["rate_per_year"] - rates[i]) / t["rate_sigma_per_year"])
    pulls = np.array(pulls)
    assert len(pulls) == 15
    assert np.all(np.abs(pulls) < 3.5), pulls  # each recovered within its own sigma (3.5 sigma bound)
    assert 0.4 < np.sqrt(np.mean(pulls**2)) < 1.6, pulls  # and the sigmas are honest: pulls ~ N(0, 1)


def test_drift_ignores_rejected_calibrations(store):
    _save_series(store, "R", [0, 365.25, 730.5], B0=(0, 0, 0), rates=(0.1, 0, 0), sigma=0.01)
    meta, cols = small_capture(device="R")
    store.save_calibration(
        accel_result(device="R", B=(5, 5, 5)),
        meta=meta,
        columns=cols,
        allow_duplicate=True,
        time="2023-06-01",
        accepted=False,
    )
    t = store.drift("R", param="B[0]")[0]
    assert t["n"] == 3 and t["rate_per_year"] == pytest.approx(0.1, abs=1e-12)


def test_tolerance_prediction(store):
    store.add_device("P", interval_days=730, tolerances={"B": 0.01})
    # three calibrations on the lines, rate sigma 0.0005 / sqrt(0.5) = 7e-4: B[0] 28σ, B[1] 5.7σ (significant)
    _save_series(store, "P", [0, 182.625, 365.25], B0=(0, 0, 0), rates=(0.02, -0.004, 0.0), sigma=0.0005)
    trends = {t["param"]: t for t in store.drift("P", param="B")}
    # B[0]: 0.01 / 0.02 per year = half a year after the last calibration (2023-01-01 + 182.625 d)
    last = T0 + timedelta(days=365.25)
    assert trends["B[0]"]["leaves_tolerance"] == (last + timedelta(days=182.625)).strftime("%Y-%m-%dT%H:%M:%SZ")
    assert trends["B[1]"]["leaves_tolerance"][:10] == (last + timedelta(days=2.5 * 365.25)).strftime("%Y-%m-%d")
    assert trends["B[2]"]["leaves_tolerance"] is None  # no drift: never
    assert trends["B[0]"]["tolerance"] == 0.01


def test_negligible_drift_predicts_no_exit(store):
    store.add_device("SLOW", tolerances={"B": 0.01})
    # sigmas far below the rates, so each trend is significant and only its slowness says "never"
    _save_series(store, "SLOW", [0, 182.625, 365.25], B0=(0, 0, 0), rates=(1e-12, -1e-9, 1e-3), sigma=1e-14)
    assert all(t["significant"] for t in store.drift("SLOW", param="B"))
    leaves = {t["param"]: t["leaves_tolerance"] for t in store.drift("SLOW", param="B")}
    assert leaves["B[0]"] is None and leaves["B[1]"] is None  # 1e7+ years: beyond any date
    last = T0 + timedelta(days=365.25)  # 0.01 / 0.001 per year = 10 years (of 365.25 d) after the last calibration
    assert leaves["B[2]"] == (last + timedelta(days=3652.5)).strftime("%Y-%m-%dT%H:%M:%SZ")


# --- due -------------------------------------------------------------------------------


def test_due_by_interval(store):
    store.add_device("I", interval_days=180)
    _save_series(store, "I", [0], B0=(0, 0, 0), rates=(0, 0, 0), sigma=0.01)  # calibrated 2022-01-01
    due_at = T0 + timedelta(days=180)
    assert store.due(now=due_at - timedelta(days=31)) == []
    soon = store.due(within_days=60, now=due_at - timedelta(days=31))
    assert [(e["device_id"], e["status"]) for e in soon] == [("I", "due")]
    assert soon[0]["days_left"] == pytest.approx(31.0)
    assert soon[0]["reasons"][0]["kind"] == "interval" and "180-day interval" in soon[0]["reason"]
    late = store.due(now=due_at + timedelta(days=10))
    assert late[0]["status"] == "overdue" and late[0]["days_left"] == pytest.approx(-10.0)
    # a new accepted calibration restarts the clock; a rejected one does not
    meta, cols = small_capture(device="I")
    store.save_calibration(
        accel_result(device="I"), meta=meta, columns=cols, allow_duplicate=True, time=due_at, accepted=False
    )
    assert [e["device_id"] for e in store.due(now=due_at + timedelta(days=10))] == ["I"]
    store.save_calibration(accel_result(device="I"), meta=meta, columns=cols, allow_duplicate=True, time=due_at)
    assert store.due(now=due_at + timedelta(days=10)) == []


def test_due_earlier_by_drift(store):
    store.add_device("F", interval_days=365, tolerances={"B[0]": 0.01})
    _save_series(store, "F", [0, 182.625, 365.25], B0=(0, 0, 0), rates=(0.02, 0, 0), sigma=0.001)
    last = T0 + timedelta(days=365.25)
    [e] = store.due(now=last + timedelta(days=200))  # interval would end at +365 d; drift leaves at +182.6 d
    assert e["reasons"][0]["kind"] == "drift" and e["reasons"][0]["param"] == "B[0]"
    assert e["days_left"] == pytest.approx(182.625 - 200, abs=1e-3)
    assert "drift of B[0]" in e["reason"]
    assert store.due(now=last + timedelta(days=150)) == []
    # loosening the tolerance moves the reminder back to the interval
    store.add_device("F", tolerances={"B[0]": 1.0})
    assert store.due(now=last + timedelta(days=200)) == []
    [e] = store.due(now=last + timedelta(days=366))
    assert e["reasons"][0]["kind"] == "interval"


def test_due_never_calibrated_and_no_interval(store):
    store.add_device("NEW")
    _save_series(store, "FOREVER", [0], B0=(0, 0, 0), rates=(0, 0, 0), sigma=0.01)  # no interval, no tolerance
    items = store.due(now=T0 + timedelta(days=10000))
    assert [(e["device_id"], e["status"]) for e in items] == [("NEW", "never calibrated")]


def test_due_handful_of_devices_sorted_soonest_first(store):
    plan = {"d1": (100, -50), "d2": (100, -10), "d3": (30, 5), "d4": (400, -200)}  # interval, days left
    now = T0 + timedelta(days=1000)
    for device, (interval, offset) in plan.items():
        store.add_device(device, interval_days=interval)
        last = 1000 - interval + offset
        _save_series(store, device, [last], B0=(0, 0, 0), rates=(0, 0, 0), sigma=0.01)
    items = store.due(within_days=7, now=now)
    assert [e["device_id"] for e in items] == ["d4", "d1", "d2", "d3"]
    assert [round(e["days_left"]) for e in items] == [-200, -50, -10, 5]
    assert store.rebuild_schedule() == 4
    assert [e["device_id"] for e in store.due(within_days=7, now=now)] == ["d4", "d1", "d2", "d3"]
