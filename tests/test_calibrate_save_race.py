"""Two `station calibrate --save` processes of one device on one database file: each result is
judged against the device's reference (its latest accepted calibration of the procedure), and
the judgement stored (previous_calibration_id, the verdict's comparison) must still be the
reference when the save lands. Real processes, a real SQLite file; the interleaving is forced
by tests/station_barrier.py (conditions, not sleeps)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import time
from pathlib import Path

from db import Store
from tests.station_run import run_station

ROOT = Path(__file__).resolve().parents[1]


def _wait_for(path: Path, proc: subprocess.Popen, timeout_s: float = 120.0) -> None:
    end = time.monotonic() + timeout_s
    while not path.exists():
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < end, f"no {path}"
        time.sleep(0.01)


def _held(tmp_path: Path, name: str, *args) -> tuple[subprocess.Popen, Path]:
    folder = tmp_path / name
    folder.mkdir()
    proc = subprocess.Popen(
        [sys.executable, str(ROOT / "tests" / "station_barrier.py"), str(folder), *map(str, args)],
        cwd=ROOT,
        text=True,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    return proc, folder


def test_a_save_judged_against_a_reference_another_process_replaced_is_judged_again(tmp_path):
    """A and B both judged against calibration #1; B saved #2; A then stored 'previous
    calibration #1' although #2 was the reference when it landed (measured before the fix:
    A's review said previous_calibration_id 1, the history had two results judged against #1).
    Now A's save finds the reference changed inside its write transaction (BEGIN IMMEDIATE),
    saves nothing, says so in one line and is judged again against #2."""
    db = tmp_path / "station.db"
    caps = []
    # each dated to the second, B's before A's: B's save is then A's reference at A's own time
    # however long the machine takes between them (a date alone is read at the clock: under load
    # B's save could fall a second after A's, making A a back-dated result that rightly keeps #1)
    for seed, when in ((1, "10:00:00"), (2, "10:00:02"), (3, "10:00:01")):
        out = tmp_path / f"c{seed}.csv"
        res = run_station("simulate", "--procedure", "accel-tabletop", "--seed", seed, "--out", out)
        assert res.returncode == 0, res.stderr
        text = out.read_text()
        assert "\n# date: " in text
        out.write_text(re.sub(r"^# date: .*$", f"# date: 2026-03-01T{when}Z", text, count=1, flags=re.M))
        caps.append(out)
    res = run_station("--db", db, "calibrate", caps[0], "--save", "--device", "DEV-1")
    assert res.returncode == 0, res.stderr

    a, a_dir = _held(tmp_path, "a", "--db", db, "calibrate", caps[1], "--save", "--device", "DEV-1", "--json")
    b, b_dir = _held(tmp_path, "b", "--db", db, "calibrate", caps[2], "--save", "--device", "DEV-1", "--json")
    _wait_for(a_dir / "judged", a)
    _wait_for(b_dir / "judged", b)  # both judged against #1
    (b_dir / "go").touch()
    b_out, b_err = b.communicate(timeout=120)
    assert b.returncode == 0, b_err
    b_res = json.loads(b_out)
    assert b_res["review"]["previous_calibration_id"] == 1
    (a_dir / "go").touch()
    a_out, a_err = a.communicate(timeout=120)
    assert a.returncode == 0, a_err
    a_res = json.loads(a_out)
    said = [line for line in a_err.splitlines() if "changed while this result was judged" in line]
    assert (
        len(said) == 1
        and "against calibration #1" in said[0]
        and f"now calibration #{b_res['calibration_id']}" in said[0]
    )
    assert a_res["review"]["previous_calibration_id"] == b_res["calibration_id"]
    with Store(str(db)) as s:
        history = s.history("DEV-1")
        stored = {c["id"]: c["review"]["previous_calibration_id"] for c in history}
    # each save judged against the one before it: a chain, no two against the same reference
    assert stored == {1: None, b_res["calibration_id"]: 1, a_res["calibration_id"]: b_res["calibration_id"]}


def test_the_store_refuses_a_save_judged_against_a_reference_no_longer_in_use(tmp_path):
    """The check itself, in the store: judged against none while #1 is in use -> nothing saved."""
    import pytest
    from db_testdata import accel_result, small_capture

    from db.store import ReferenceChanged

    db = str(tmp_path / "s.db")
    with Store(db) as s:
        meta, cols = small_capture(device="D")
        first = s.save_calibration(accel_result(device="D"), meta=meta, columns=cols, judged_reference=None)
        meta2, cols2 = small_capture(device="D", seed=2)
        with pytest.raises(
            ReferenceChanged, match=f"judged against no previous calibration: it is now calibration #{first}"
        ):
            s.save_calibration(accel_result(device="D"), meta=meta2, columns=cols2, judged_reference=None)
        assert len(s.history("D")) == 1
        assert s.save_calibration(accel_result(device="D"), meta=meta2, columns=cols2, judged_reference=first) > first


def test_the_results_screen_judges_again_when_another_process_saved_meanwhile(tmp_path):
    """The Results screen (real app, pilot) shows a result judged against calibration #1; while
    it is open, another process (`station calibrate --save`) saves #2 of the same device. `s`
    then saved 'previous #1' over #2; now nothing is saved, the screen says why, shows the
    result judged against #2, and the next `s` saves it with previous_calibration_id #2."""
    import asyncio

    from station.app import make_app
    from station.screens.results import ResultsScreen
    from tests.test_tui import SIZE, text_of, wait_for
    from tests.tui_data import p1_result, seed_history

    db = tmp_path / "station.db"
    seed_history(str(db), "IMU-7", n=1)
    with Store(str(db)) as s:
        previous = s.history("IMU-7")[-1]
    cap, result = p1_result("IMU-7", drift=0.02, date="2026-03-01")
    other = tmp_path / "other.csv"
    assert run_station("simulate", "--procedure", "accel-tabletop", "--seed", 4, "--out", other).returncode == 0
    # dated between #1 (2024-03-01) and the result (2026-03-01): it becomes the calibration in use at
    # the result's date, its reference (one dated after the result would not be: a back-dated result
    # is judged against the calibration of its own date, tests/test_calibrate_back_dated.py)
    text = other.read_text()
    assert "\n# date: " in text
    other.write_text(re.sub(r"^# date: .*$", "# date: 2026-02-01", text, count=1, flags=re.M))

    async def story():
        app = make_app(str(db), device_id="IMU-7")
        async with app.run_test(size=SIZE) as pilot:
            await app.push_screen(ResultsScreen(cap, result, None, previous))
            await wait_for(pilot, lambda: app.screen.query_one("#params").row_count > 0)
            assert f"previous #{previous['id']}" in text_of(app, "#summary")
            # another station saves meanwhile: a real process on the same file
            res = subprocess.run(
                [
                    sys.executable,
                    "-m",
                    "station",
                    "--db",
                    str(db),
                    "calibrate",
                    str(other),
                    "--save",
                    "--device",
                    "IMU-7",
                ],
                cwd=ROOT,
                capture_output=True,
                text=True,
                timeout=120,
            )
            assert res.returncode == 0, res.stderr
            with Store(str(db)) as s:
                second = s.reference("IMU-7", "accel-tabletop")["id"]
            await pilot.press("s")
            await wait_for(pilot, lambda: "Not saved" in text_of(app, "#saved"))
            said = text_of(app, "#saved")
            assert f"now calibration #{second}" in said and "judged again" in said
            assert f"previous #{second}" in text_of(app, "#summary")
            assert app.screen.calibration_id is None
            await pilot.press("s")
            await wait_for(pilot, lambda: app.screen.calibration_id is not None)
            return app.screen.calibration_id, second

    cal_id, second = asyncio.run(story())
    with Store(str(db)) as s:
        assert s.calibration(cal_id)["review"]["previous_calibration_id"] == second
        assert len(s.history("IMU-7")) == 3
