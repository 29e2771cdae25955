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
from db.params import iso
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


def _dated(path, src, date_lines):
    """``src`` with its ``# date:`` line replaced by ``date_lines``."""
    path.write_text(re.sub(r"^# date: .*$", date_lines, src.read_text(), count=1, flags=re.M))
    return path


def test_a_capture_dated_today_saved_after_a_calibration_of_this_morning_is_in_use(tmp_path, captures):
    """A calibration saved earlier today with its time of day (the TUI saves its run's start),
    then `calibrate --save` of a capture whose `date` is today's date alone (no time, no
    `recorded_at`: `station simulate`, a CSV written by hand). The date alone read as midnight:
    the new one sorted before this morning's, was judged against the one before it, and this
    morning's stayed in use, with a back-dated note. A date alone on the day of the save now
    reads as the save's time. Real CLI in subprocesses, a real SQLite file."""
    from datetime import UTC, datetime, timedelta

    now = datetime.now(UTC).replace(microsecond=0)
    # earlier today: an hour ago, or midnight when the day is younger than that
    morning = max(now - timedelta(hours=1), now.replace(hour=0, minute=0, second=0))
    db = tmp_path / "station.db"
    first = _dated(tmp_path / "morning.csv", captures[1], f"# date: {morning.isoformat().replace('+00:00', 'Z')}")
    res = run_station("--db", db, "calibrate", first, "--save", "--device", "DEV-1", "--json", subprocess_run=True)
    assert res.returncode == 0, res.stderr
    morning_id = json.loads(res.stdout)["calibration_id"]
    day = datetime.now(UTC).date().isoformat()  # read again: the save above may have crossed midnight
    later = _dated(tmp_path / "today.csv", captures[2], f"# date: {day}")
    res = run_station("--db", db, "calibrate", later, "--save", "--device", "DEV-1", "--json", subprocess_run=True)
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    assert "note:" not in res.stderr, res.stderr  # before: "... is dated <today>, before #1 of <today> ..."
    assert out["review"]["previous_calibration_id"] == morning_id
    with Store(str(db)) as s:
        saved = s.calibration(out["calibration_id"])
        assert saved["time"][:10] == day and saved["time"] >= iso(morning)
        assert saved["supersedes"] == morning_id and saved["superseded_by"] is None
        assert s.reference("DEV-1", "accel-tabletop")["id"] == out["calibration_id"]
        assert s.calibration(morning_id)["superseded_by"] == out["calibration_id"]
        assert s.verify() == []


def test_a_capture_dated_a_past_day_sorts_after_the_calibrations_of_that_day(tmp_path, captures):
    """A date alone from a past day (a file calibrated the next morning) is that day's last second:
    after a calibration saved with a time of day on the same date (before: midnight, before it,
    which stayed in use), and still before a calibration of a later date (back-dated, as before)."""
    db = tmp_path / "station.db"
    timed = _dated(tmp_path / "timed.csv", captures[1], "# date: 2026-01-10T10:00:00Z")
    res = run_station("--db", db, "calibrate", timed, "--save", "--device", "DEV-1", "--json", subprocess_run=True)
    assert res.returncode == 0, res.stderr
    timed_id = json.loads(res.stdout)["calibration_id"]
    res = run_station("--db", db, "calibrate", captures[3], "--save", "--device", "DEV-1", "--json")
    assert res.returncode == 0, res.stderr
    march = json.loads(res.stdout)["calibration_id"]
    day = _dated(tmp_path / "day.csv", captures[2], "# date: 2026-01-10")
    res = run_station("--db", db, "calibrate", day, "--save", "--device", "DEV-1", "--json", subprocess_run=True)
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    assert out["review"]["previous_calibration_id"] == timed_id
    # back-dated before March, not before the morning of its own date
    assert f"before #{march} of 2026-03-10" in res.stderr, res.stderr
    with Store(str(db)) as s:
        saved = s.calibration(out["calibration_id"])
        assert saved["time"] == "2026-01-10T23:59:59Z"
        assert saved["supersedes"] == timed_id and saved["superseded_by"] == march
        assert s.calibration(timed_id)["superseded_by"] == out["calibration_id"]
        assert s.verify() == []


@pytest.mark.parametrize(
    ("saved_at", "stored"),
    [
        ("2026-01-10T15:30:12Z", "2026-01-10T15:30:12Z"),  # saved on its date: the save's time
        ("2026-01-11T00:10:00Z", "2026-01-10T23:59:59Z"),  # a later day: its date's last second
        ("2026-01-09T23:30:00Z", "2026-01-10T00:00:00Z"),  # still ahead (east of UTC): its first
    ],
)
def test_a_date_alone_is_the_time_of_the_save_moved_into_its_date(saved_at, stored):
    """The one rule (db.params.capture_time), continuous in the save's time: no jump at midnight
    UTC, which a bench west of UTC passes in its working afternoon."""
    from db.params import capture_time

    assert capture_time({"date": "2026-01-10"}, saved_at) == stored
    assert capture_time({"date": "2026-01-10T08:00:00Z"}, saved_at) == "2026-01-10T08:00:00Z"
    rec = {"date": "2026-01-10", "recorded_at": "2026-01-10T14:00:00Z"}
    assert capture_time(rec, saved_at) == "2026-01-10T14:00:00Z"


def test_the_later_calibration_says_a_back_dated_one_was_saved_before_it(tmp_path, captures):
    """#1 January, #2 March, then February saved: #2 stays in use, and `calibrate --save` said so
    once. Its own views said nothing afterwards (before: `history` showed #2 with no word,
    `devices show` its id and date, the report "Compared with calibration #1 ..., the calibration
    in use before this one" while the history put February between). Each now says, in one
    line, which calibration dated before it was saved after it, its date and when it was saved.
    Real CLI in subprocesses, a real SQLite file."""
    db = _db_with_january_and_march(tmp_path, captures)
    rejected = _dated(tmp_path / "rejected.csv", captures[2], "# date: 2026-02-20")
    res = run_station("--db", db, "calibrate", rejected, "--save", "--device", "DEV-1", "--reject", "bad mount")
    assert res.returncode == 3, res.stderr  # rejected: neither precedes #2 nor is said to
    res = run_station("--db", db, "calibrate", captures[2], "--save", "--device", "DEV-1", "--json")
    assert res.returncode == 0, res.stderr
    feb = json.loads(res.stdout)["calibration_id"]
    with Store(str(db)) as s:
        saved_at = s.calibration(feb)["saved_at"][:16].replace("T", " ")
    said = f"#{feb} dated 2026-02-10, saved {saved_at} UTC after #2, now precedes it; #2 stays as judged against #1"

    res = run_station("--db", db, "history", "DEV-1", subprocess_run=True)
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    at = next(i for i, line in enumerate(lines) if line.startswith("#2 "))
    assert lines[at + 1] == f"    note: {said}", res.stdout
    assert sum("note:" in line for line in lines) == 1, res.stdout  # only on #2 (not on the rejected #3)
    records = json.loads(run_station("--db", db, "history", "DEV-1", "--json", subprocess_run=True).stdout)
    assert {r["id"]: r["back_dated_before"] for r in records} == {1: [], 2: [feb], 3: [], feb: []}

    res = run_station("--db", db, "devices", "show", "DEV-1", subprocess_run=True)
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    at = lines.index(next(line for line in lines if line.startswith("latest accel-tabletop: #2 ")))
    assert lines[at + 1] == f"  note: {said}", res.stdout
    shown = json.loads(run_station("--db", db, "devices", "show", "DEV-1", "--json", subprocess_run=True).stdout)
    assert shown["latest"]["accel-tabletop"]["back_dated_before"] == [feb]

    res = run_station("--db", db, "report", 2, "-o", "-", subprocess_run=True)
    assert res.returncode == 0, res.stderr
    assert f"<p id='back-dated'>Back-dated since: {said}.</p>" in res.stdout
    res = run_station("--db", db, "report", feb, "-o", "-", subprocess_run=True)
    assert res.returncode == 0 and "back-dated" not in res.stdout


def test_history_screen_says_a_back_dated_one_was_saved_before_the_highlighted_calibration(tmp_path):
    """The History screen (real app, pilot, 80x24, a real SQLite file): #1 2024-03-01, #2
    2025-03-01, then a capture dated 2024-09-01 saved (#3). With #2 highlighted (the newest row,
    where the screen opens) the line under the calibrations says #3, its date and when it was
    saved, whole on the screen; on #3 and #1 there is no line. Before: the rows only, #2 "in use"."""
    import asyncio

    from station.app import make_app
    from station.store import save_result
    from tests.test_tui import SIZE, wait_for, words_of
    from tests.tui_data import p1_result, seed_history

    db = tmp_path / "station.db"
    seed_history(str(db), "IMU-7", n=2)  # #1 2024-03-01, #2 2025-03-01
    cap, result = p1_result("IMU-7", drift=0.01, date="2024-09-01")
    back = save_result(str(db), cap, result, device_id="IMU-7", judged_reference={"id": 1})
    with Store(str(db)) as s:
        saved = s.calibration(back)["saved_at"][:16].replace("T", " ")

    async def story():
        app = make_app(str(db), device_id="IMU-7", start="history")
        async with app.run_test(size=SIZE) as pilot:
            await wait_for(pilot, lambda: app.screen.query_one("#calibrations").row_count == 3)
            # shown, not only displayed: the region is laid out a refresh after display is set
            await wait_for(pilot, lambda: words_of(app, "#calnote"))
            shown = words_of(app, "#calnote")  # wrapped in the right-hand column
            # without "; #2 stays as judged against #1" (history, the report): two rows, not three
            assert shown == f"#{back} dated 2024-09-01, saved {saved} UTC after #2, now precedes it"
            assert app.screen.query_one("#calnote").region.height == 2
            table = app.screen.query_one("#calibrations")
            table.focus()
            for _ in range(2):  # #3, then #1: nothing to say
                await pilot.press("down")
                await wait_for(pilot, lambda: not app.screen.query_one("#calnote").display)
            await pilot.press("up", "up")
            await wait_for(pilot, lambda: app.screen.query_one("#calnote").display)

    asyncio.run(story())
