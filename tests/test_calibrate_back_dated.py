"""A back-dated capture: `station calibrate old.csv --save` after newer calibrations of the device
were saved. The bench engineer's expectation: the result is judged against the calibration in use
at the capture's own date, supersedes that same one, and takes its place in the history at its
date; the later calibrations keep their records (hashed into the chain) and stay in use; history,
drift, due and verify stay right; the save says where it landed in one line. Real CLI, a real
SQLite file, captures from `station simulate` with their `date` set.

Measured before the fix (the repro in test_back_dated_result_is_judged_against_the_calibration_of_its_date):
the February result was judged against March's #2 (FAIL, B[1] changed +1.2 m/s^2, exit 1;
with --override it stored previous_calibration_id 2 but supersedes 1), and `history` said
"#1 superseded by #2" and showed #3 with no successor, as if it were in use.
"""

from __future__ import annotations

import json
import re

import pytest

from db import Store
from tests.station_run import run_station

# seeds whose simulated units differ so that a 1 m/s^2 tolerance on B tells them apart:
# seed 2 is within 0.63 m/s^2 of seed 1 and 1.2 m/s^2 from seed 3 (measured: calibrate --json)
DATES = {1: "2026-01-10", 2: "2026-02-10", 3: "2026-03-10"}
TOLERANCE_B_MPS2 = 1.0


@pytest.fixture(scope="module")
def captures(tmp_path_factory):
    folder = tmp_path_factory.mktemp("back_dated")
    out = {}
    for seed, date in DATES.items():
        path = folder / f"c{seed}.csv"
        res = run_station("simulate", "--procedure", "accel-tabletop", "--seed", seed, "--out", path)
        assert res.returncode == 0, res.stderr
        text = path.read_text()
        assert re.search(r"^# date: .*$", text, flags=re.M)
        path.write_text(re.sub(r"^# date: .*$", f"# date: {date}", text, count=1, flags=re.M))
        out[seed] = path
    return out


def _db_with_january_and_march(tmp_path, captures):
    db = tmp_path / "station.db"
    assert run_station("--db", db, "devices", "add", "DEV-1", "--interval-days", 365).returncode == 0
    for seed in (1, 3):
        res = run_station("--db", db, "calibrate", captures[seed], "--save", "--device", "DEV-1")
        assert res.returncode == 0, res.stderr
    res = run_station("--db", db, "devices", "add", "DEV-1", "--tolerance", f"B={TOLERANCE_B_MPS2}")
    assert res.returncode == 0, res.stderr
    return db


def test_back_dated_result_is_judged_against_the_calibration_of_its_date(tmp_path, captures):
    db = _db_with_january_and_march(tmp_path, captures)
    res = run_station("--db", db, "calibrate", captures[2], "--save", "--device", "DEV-1", "--json")
    # judged against January's #1 (it passes), not March's #2 (it would fail by 1.2 m/s^2)
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    assert out["review"]["verdict"] == "pass" and out["review"]["previous_calibration_id"] == 1
    cal_id = out["calibration_id"]
    lines = res.stderr.splitlines()
    assert lines[0] == f"station: saved calibration {cal_id} as accepted"
    # one line says where it landed and that #2 is not judged again
    assert len(lines) == 2 and lines[1].startswith("station: note: "), res.stderr
    assert "dated 2026-02-10, before #2 of 2026-03-10" in lines[1]
    assert "judged when saved against #1, not judged again" in lines[1]
    with Store(str(db)) as s:
        saved = s.calibration(cal_id)
        # what it was judged against is what it supersedes
        assert saved["supersedes"] == saved["review"]["previous_calibration_id"] == 1
        assert saved["superseded_by"] == 2
        assert s.reference("DEV-1", "accel-tabletop")["id"] == 2  # March stays in use
        assert s.calibration(1)["superseded_by"] == cal_id
        assert s.calibration(2)["superseded_by"] is None
        assert s.verify() == []


def test_history_drift_and_due_follow_the_dates(tmp_path, captures):
    db = _db_with_january_and_march(tmp_path, captures)
    res = run_station("--db", db, "calibrate", captures[2], "--save", "--device", "DEV-1", "--json")
    assert res.returncode == 0, res.stderr
    feb = json.loads(res.stdout)["calibration_id"]
    res = run_station("--db", db, "history", "DEV-1")
    assert res.returncode == 0, res.stderr
    heads = [line for line in res.stdout.splitlines() if line.startswith("#")]
    assert [h.split()[0] for h in heads] == ["#1", f"#{feb}", "#2"]
    assert f"accepted, superseded by #{feb}" in heads[0]
    assert "accepted, superseded by #2" in heads[1]
    assert "superseded" not in heads[2]  # the one in use
    trends = json.loads(run_station("--db", db, "drift", "DEV-1", "--param", "B[1]", "--json").stdout)
    assert trends[0]["calibration_ids"] == [1, feb, 2] and trends[0]["times"][1].startswith("2026-02-10")
    due = json.loads(run_station("--db", db, "due", "--within", 1000, "--json").stdout)
    assert due[0]["reasons"][0]["last_calibration_id"] == 2
    assert due[0]["due"].startswith("2027-03-10")  # 365 days after March, not after February
    assert run_station("--db", db, "verify").returncode == 0


def test_back_dated_failure_names_the_calibration_of_its_date(tmp_path, captures):
    """The February result judged against January fails a tighter tolerance by January's
    difference (B[2] -0.63 m/s^2), not March's; --reject keeps it out of the chain: no note."""
    db = _db_with_january_and_march(tmp_path, captures)
    assert run_station("--db", db, "devices", "add", "DEV-1", "--tolerance", "B=0.5").returncode == 0
    res = run_station("--db", db, "calibrate", captures[2], "--save", "--device", "DEV-1")
    assert res.returncode == 1, res.stderr
    assert "B[2] changed" in res.stderr and "B[1] changed" not in res.stderr  # vs March: B[1] +1.2
    res = run_station("--db", db, "calibrate", captures[2], "--save", "--device", "DEV-1", "--reject", "bad", "--json")
    assert res.returncode == 3, res.stderr
    assert json.loads(res.stdout)["review"]["previous_calibration_id"] == 1
    assert "note:" not in res.stderr
    with Store(str(db)) as s:
        assert s.calibration(1)["superseded_by"] == 2
        assert s.verify() == []


def test_result_dated_after_the_latest_is_unchanged(tmp_path, captures):
    """The ordinary case keeps its behaviour: judged against the latest, supersedes it, no note."""
    db = tmp_path / "station.db"
    for seed in (1, 2):
        res = run_station("--db", db, "calibrate", captures[seed], "--save", "--device", "DEV-1", "--json")
        assert res.returncode == 0, res.stderr
        assert "note:" not in res.stderr
    out = json.loads(res.stdout)
    assert out["review"]["previous_calibration_id"] == 1
    with Store(str(db)) as s:
        assert s.calibration(out["calibration_id"])["supersedes"] == 1
        assert s.calibration(1)["superseded_by"] == out["calibration_id"]


def test_history_of_a_save_without_judgement_follows_the_dates(tmp_path):
    """The store alone (imports and tools save without a judgement): a calibration saved after a
    later-dated one is superseded by it in the history (before: no successor, shown as in use)."""
    from db_testdata import accel_result, small_capture

    with Store(str(tmp_path / "s.db")) as s:
        meta, cols = small_capture(device="D")
        june = s.save_calibration(accel_result(device="D"), meta=dict(meta, date="2025-06-01"), columns=cols)
        meta2, cols2 = small_capture(device="D", seed=2)
        jan = s.save_calibration(accel_result(device="D"), meta=dict(meta2, date="2024-01-01"), columns=cols2)
        by_id = {c["id"]: c for c in s.history("D")}
        assert by_id[jan]["superseded_by"] == june and by_id[june]["superseded_by"] is None
        assert s.calibration(jan)["superseded_by"] == june
        assert [c["id"] for c in s.later(jan)] == [june] and s.later(june) == []


def test_results_screen_judges_a_back_dated_result_against_the_calibration_of_its_date(tmp_path):
    """The Results screen (real app, pilot) given the latest calibration as `previous` for a
    result dated between two saved ones (what the Import screen passed before the fix): `s`
    saved 'previous #2' while superseding #1. Now the save finds #1 in use at the result's
    date, saves nothing, shows the result judged against #1, and the next `s` saves it so."""
    import asyncio

    from station.app import make_app
    from station.screens.results import ResultsScreen
    from tests.test_tui import SIZE, text_of, wait_for
    from tests.tui_data import p1_result, seed_history

    db = tmp_path / "station.db"
    seed_history(str(db), "IMU-7", n=2)  # #1 2024-03-01, #2 2025-03-01
    with Store(str(db)) as s:
        first, latest = (c["id"] for c in s.history("IMU-7"))
        stale = s.reference("IMU-7", "accel-tabletop")
    cap, result = p1_result("IMU-7", drift=0.01, date="2024-09-01")

    async def story():
        app = make_app(str(db), device_id="IMU-7")
        async with app.run_test(size=SIZE) as pilot:
            await app.push_screen(ResultsScreen(cap, result, None, stale))
            await wait_for(pilot, lambda: app.screen.query_one("#params").row_count > 0)
            await pilot.press("s")
            await wait_for(pilot, lambda: "Not saved" in text_of(app, "#saved"))
            assert f"previous #{first}" in text_of(app, "#summary")
            await pilot.press("s")
            await wait_for(pilot, lambda: app.screen.calibration_id is not None)
            # where it went in the history is said, as calibrate --save says it
            await wait_for(pilot, lambda: any("before #" in str(n.message) for n in app._notifications))
            return app.screen.calibration_id

    cal_id = asyncio.run(story())
    with Store(str(db)) as s:
        saved = s.calibration(cal_id)
        assert saved["supersedes"] == saved["review"]["previous_calibration_id"] == first
        assert saved["superseded_by"] == latest
        assert s.verify() == []


def test_the_save_checks_the_reference_at_the_results_own_date(tmp_path):
    """Inside the save's transaction the reference is read at the result's date: a calibration
    saved meanwhile with a later date does not make a February judgement stale (before the fix:
    ReferenceChanged, as the latest had changed), one dated between does (nothing saved)."""
    from db_testdata import accel_result, small_capture

    from db.store import ReferenceChanged

    def cap(seed, date):
        meta, cols = small_capture(device="D", seed=seed)
        return dict(meta, date=date), cols

    with Store(str(tmp_path / "s.db")) as s:
        meta, cols = cap(1, "2026-01-10")
        jan = s.save_calibration(accel_result(device="D"), meta=meta, columns=cols, judged_reference=None)
        meta, cols = cap(2, "2026-03-10")
        s.save_calibration(accel_result(device="D"), meta=meta, columns=cols, judged_reference=jan)
        meta, cols = cap(3, "2026-02-10")  # judged against January, the calibration of its date
        feb = s.save_calibration(accel_result(device="D"), meta=meta, columns=cols, judged_reference=jan)
        assert s.calibration(feb)["supersedes"] == jan
        meta, cols = cap(4, "2026-02-20")  # judged against January too, but February landed meanwhile
        with pytest.raises(ReferenceChanged, match=f"judged against calibration #{jan}: it is now calibration #{feb}"):
            s.save_calibration(accel_result(device="D"), meta=meta, columns=cols, judged_reference=jan)
        assert len(s.history("D")) == 3


def test_a_recording_dated_the_same_day_as_a_timed_calibration_follows_it(tmp_path, captures):
    """`station record` writes `date` (the day) and `recorded_at` (its time). A date alone read as
    midnight, so a recording saved in the afternoon sorted before a calibration saved that morning
    with its time of day (the TUI's): it was judged against the one before, and the morning's
    stayed in use. Its time of day now counts."""
    db = tmp_path / "station.db"
    assert run_station("--db", db, "devices", "add", "DEV-1", "--interval-days", 365).returncode == 0
    text = captures[1].read_text()
    morning, afternoon = tmp_path / "morning.csv", tmp_path / "afternoon.csv"
    morning.write_text(re.sub(r"^# date: .*$", "# date: 2026-01-10T10:00:00Z", text, count=1, flags=re.M))
    day = "# date: 2026-01-10\n# recorded_at: 2026-01-10T14:00:00Z"
    afternoon.write_text(re.sub(r"^# date: .*$", day, text, count=1, flags=re.M))
    ids = []
    for path in (morning, afternoon):
        res = run_station("--db", db, "calibrate", path, "--save", "--device", "DEV-1", "--json")
        assert res.returncode == 0, res.stderr
        ids.append(json.loads(res.stdout)["calibration_id"])
        assert "before #" not in res.stderr, res.stderr
    with Store(str(db)) as s:
        later = s.calibration(ids[1])
        assert later["time"] == "2026-01-10T14:00:00Z"
        assert later["supersedes"] == ids[0] and later["superseded_by"] is None
        assert s.calibration(ids[0])["superseded_by"] == ids[1]
        assert s.reference("DEV-1", "accel-tabletop")["id"] == ids[1]
