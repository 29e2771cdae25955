"""Accept, reject or re-do, never silently: the review rules of `calibrate --save` and the
store (real CLI, real SQLite, captures from the simulator; see README "Accepting a result")."""

from __future__ import annotations

import json

import numpy as np
import pytest
from station_run import run_station

from db import Store
from db.integrity import record_hash
from station.calibrate import calibrate_capture
from station.capture import read_capture, write_capture
from station.procedures.review import assess, fit_checks, review_record


def _sim(tmp_path, procedure, seed, name=None, *options):
    out = tmp_path / (name or f"{procedure}-{seed}.csv")
    args = ["simulate", "--procedure", procedure, "--seed", seed, "--out", out]
    for o in options:
        args += ["--option", o]
    r = run_station(*args)
    assert r.returncode == 0, r.stderr
    return out


def _save(db, path, *extra):
    return run_station("calibrate", path, "--save", "--json", "--db", db, *extra)


def test_calibrate_save_exit_status_follows_the_decision(tmp_path):
    """0 accepted, 1 FAIL not saved, 3 saved as rejected, 2 the same capture again."""
    db = tmp_path / "s.db"
    first = _sim(tmp_path, "accel-tabletop", 1)
    device = read_capture(first).meta["device"]
    r = _save(db, first)
    assert r.returncode == 0, r.stderr
    first_id = json.loads(r.stdout)["calibration_id"]
    assert json.loads(r.stdout)["review"]["decision"] == "accepted"

    # A tolerance far tighter than what two simulated units differ by: the next one fails.
    assert run_station("devices", "add", device, "--tolerance", "B=1e-6", "--db", db).returncode == 0
    second = _sim(tmp_path, "accel-tabletop", 2, None, "label_positions=1")
    cap = read_capture(second)
    cap.meta["device"] = device
    write_capture(second, cap)
    r = _save(db, second)
    assert r.returncode == 1
    assert "FAIL, not saved" in r.stderr and "B[" in r.stderr and r.stderr.count("\n") == 1
    review = json.loads(r.stdout)["review"]
    assert review["verdict"] == "fail" and review["decision"] is None
    assert review["previous_calibration_id"] == first_id
    with Store(str(db)) as s:
        assert len(s.history(device)) == 1  # nothing saved

    r = _save(db, second, "--reject", "bias jumped: unit dropped on the floor")
    assert r.returncode == 3, r.stderr
    rejected_id = json.loads(r.stdout)["calibration_id"]
    with Store(str(db)) as s:
        cal = s.calibration(rejected_id)
        assert cal["accepted"] is False
        assert cal["review"]["decision"] == "rejected" and "dropped" in cal["review"]["note"]
        assert cal["review"]["verdict"] == "fail" and cal["review"]["reasons"]
        # the rejected one is not the reference: the calibration in use is still the first
        assert s.reference(device, "accel-tabletop")["id"] == first_id
        assert s.verify() == []

    # The same capture again: refused, one line, nothing stored.
    r = _save(db, second, "--reject", "again")
    assert r.returncode == 2 and "already saved" in r.stderr and f"#{rejected_id}" in r.stderr
    assert r.stdout == ""

    # A third unit compared with the first (not the rejected second) and overridden.
    third = _sim(tmp_path, "accel-tabletop", 3)
    cap = read_capture(third)
    cap.meta["device"] = device
    write_capture(third, cap)
    r = _save(db, third)
    assert r.returncode == 1
    assert json.loads(r.stdout)["review"]["previous_calibration_id"] == first_id
    r = _save(db, third, "--override", "new sensor fitted, see work order 17")
    assert r.returncode == 0, r.stderr
    with Store(str(db)) as s:
        cal = s.calibration(json.loads(r.stdout)["calibration_id"])
        assert cal["accepted"] is True and cal["review"]["decision"] == "override"
        assert cal["supersedes"] == first_id
        assert s.verify() == []


def test_absolute_limits_fail_a_result_with_no_previous(tmp_path):
    """Limits need no previous calibration: a P2 scale factor outside them fails at once."""
    db = tmp_path / "s.db"
    path = _sim(tmp_path, "accel-centrifuge", 1)
    cap = read_capture(path)
    S = calibrate_capture(cap)["params"]["S"]
    device = cap.meta["device"]
    lo = min(S) * 1.01  # the lowest scale factor ends up 1 % below the lower limit
    r = run_station("devices", "add", device, "--limit", f"S={lo}:10", "--db", db)
    assert r.returncode == 0, r.stderr
    r = _save(db, path)
    assert r.returncode == 1
    reasons = json.loads(r.stdout)["review"]["reasons"]
    assert any("outside its limits" in x and "g per g" in x for x in reasons)
    assert run_station("devices", "add", device, "--limit", "S=2:1", "--db", db).returncode == 2


def test_a_stopped_centrifuge_fails_the_fits_own_checks(tmp_path):
    """Rows stored with the asked speeds while the centrifuge stood still (issue 15): the
    accelerometer saw only gravity, in each mounting's direction. The fit still returns
    numbers; its own checks must fail it."""
    cap = read_capture(_sim(tmp_path, "accel-centrifuge", 4))
    rng = np.random.default_rng(4)
    pos = cap.columns["position"]
    gdir = {p: v / np.linalg.norm(v) for p, v in ((p, rng.standard_normal(3)) for p in sorted(set(pos)))}
    G = np.array([gdir[p] for p in pos])
    for i, axis in enumerate(("ax", "ay", "az")):
        cap.columns[axis] = 0.3 + 1.2 * G[:, i] + 0.002 * rng.standard_normal(cap.n_rows)
    result = calibrate_capture(cap)
    checks = fit_checks(result)
    assert checks and "does not describe" in checks[0]
    a = assess(result)
    assert a.failed and a.checks == checks
    with pytest.raises(ValueError):
        review_record(a, "accepted")
    with pytest.raises(ValueError):
        review_record(a, "override", "  ")
    assert review_record(a, "override", "bench test")["decision"] == "override"
    # the same capture, spinning: passes
    good = calibrate_capture(read_capture(tmp_path / "accel-centrifuge-4.csv"))
    assert fit_checks(good) == []


def test_every_sigma_above_its_value_is_a_failed_fit():
    """The P2 case of issue 15: every σ larger than its value."""
    result = {
        "procedure": "accel-centrifuge",
        "params": {"S": [0.1, -0.2, 0.05], "b": [1.0, 2.0, -1.0]},
        "uncertainty": {"S": [0.5, 0.4, 0.3], "b": [3.0, 2.5, 1.1]},
        "residual_rms": 0.01,
    }
    assert any("every parameter" in c for c in fit_checks(result))
    result["uncertainty"]["S"][0] = 0.01
    assert fit_checks(result) == []
    # a gyro whose drift is indistinguishable from zero is a good gyro
    gyro = {
        "procedure": "gyro-drift",
        "params": {"drift": [1e-7, -2e-7, 0.0]},
        "uncertainty": {"drift": [1e-6, 1e-6, 1e-6]},
        "residual_rms": 1e-3,
    }
    assert fit_checks(gyro) == []


def test_a_documented_null_outside_the_core_parameters_is_not_a_failed_fit():
    """A compass capture without a place has no IGRF reference (its reference.* null, as the
    README says) and a P4 record without a latitude no Earth rate: both failed 'the fit
    returned non-finite values', so a result the station documents could only be saved by
    override. A null core parameter still fails."""
    compass = {
        "procedure": "compass",
        "params": {
            "hard_iron": [-0.0065, -0.105, 0.020],
            "soft_iron": [[0.98, 0.004, 0.059], [0.0, 0.92, -0.093], [0.0, 0.0, 1.10]],
            "reference": {"total_nT": None, "inclination_deg": None},
        },
        "uncertainty": {
            "hard_iron": [5e-5, 4e-5, 4e-5],
            "soft_iron": [[1.5e-4] * 3] * 3,
            "reference": {"total_nT": None, "inclination_deg": None},
        },
        "residual_rms": 228.0,
    }
    assert fit_checks(compass) == []
    compass["params"]["hard_iron"][1] = None
    assert fit_checks(compass) == ["the fit returned non-finite values"]
    gyro = {
        "procedure": "gyro-drift",
        "params": {"drift": [-1.3e-3, 2.8e-3, -2.1e-3], "earth_rate_body": None},
        "uncertainty": {"drift": [1e-4] * 3, "earth_rate_body": None},
        "residual_rms": 1e-3,
    }
    assert fit_checks(gyro) == []


def test_real_captures_without_a_place_save_as_accepted(tmp_path, shared_data):
    """End to end on the shared data: the sunsided sphere (no place) and PX4's sample.ulg
    (no latitude) save as accepted, no decision asked."""
    db = tmp_path / "s.db"
    for args in (
        [shared_data / "sunsided_marg" / "sunsided_full_sphere.capture.csv"],
        [shared_data / "px4_ulog" / "original" / "sample.ulg", "--procedure", "gyro-drift"],
    ):
        res = run_station("calibrate", *args, "--save", "--db", db)
        assert res.returncode == 0, res.stderr
        assert "saved calibration" in res.stderr and "as accepted" in res.stderr


def test_store_refuses_the_same_samples_twice_whoever_saves_them(tmp_path):
    path = _sim(tmp_path, "gyro-drift", 1)
    cap = read_capture(path)
    result = calibrate_capture(cap)
    with Store(str(tmp_path / "s.db")) as s:
        first = s.save_calibration(result, meta=cap.meta, columns=cap.columns, operator="ann", host="a")
        from db.store import DuplicateCapture

        with pytest.raises(DuplicateCapture) as e:
            s.save_calibration(result, meta=cap.meta, columns=cap.columns, operator="bob", host="b")
        assert e.value.calibration_id == first
        assert s.find_duplicate(cap.meta, cap.columns)["calibration_id"] == first
        changed = dict(cap.columns, gx=cap.columns["gx"] + 1e-12)
        assert s.find_duplicate(cap.meta, changed) is None
        assert len(s.history(cap.meta["device"])) == 1


def test_review_is_hashed_and_old_records_keep_their_hash(tmp_path):
    """A database written before migration 0002: opening it adds the columns, its records
    still verify, and an edited review on a new record is caught."""
    from db_testdata import database_before

    path = str(tmp_path / "old.db")
    conn = database_before(path, 1)
    conn.execute("INSERT INTO devices (id, created) VALUES ('OLD-1', '2024-01-01T00:00:00Z')")
    row = {
        "id": 1,
        "device_id": "OLD-1",
        "procedure": "gyro-drift",
        "time": "2024-01-01T00:00:00Z",
        "model": "m",
        "params": '{"drift":[0.1,0.2,0.3]}',
        "uncertainty": '{"drift":[0.01,0.01,0.01]}',
        "residual_rms": 0.1,
        "n_positions": 1,
        "warnings": "[]",
        "result_extra": "{}",
        "software_version": "0.1.0",
        "capture_id": None,
        "capture_sha256": None,
        "operator": "ann",
        "host": "h",
        "accepted": 1,
        "supersedes": None,
        "saved_at": "2024-01-01T00:00:00.000000Z",
        "record_version": 1,
        "prev_hash": None,
    }
    row["hash"] = record_hash(row)
    conn.execute(
        f"INSERT INTO calibrations ({', '.join(row)}) VALUES ({', '.join('?' * len(row))})", list(row.values())
    )
    # the schedule row the station wrote with it (derived: no interval, no tolerance)
    conn.execute(
        "INSERT INTO schedule (device_id, procedure, last_calibration_id, last_calibrated) "
        "VALUES ('OLD-1', 'gyro-drift', 1, '2024-01-01T00:00:00Z')"
    )
    conn.commit()
    conn.close()

    cap = read_capture(_sim(tmp_path, "gyro-drift", 2))
    with Store(path) as s:
        assert s.verify() == []
        assert s.calibration(1)["review"] is None
        assert s.get_device("OLD-1")["limits"] == {}
        a = assess(calibrate_capture(cap))
        cid = s.save_calibration(
            calibrate_capture(cap),
            meta=cap.meta,
            columns=cap.columns,
            device_id="OLD-1",
            review=review_record(a, "accepted"),
        )
        assert s.verify() == []
        assert s.reference("OLD-1", "gyro-drift")["id"] == cid
        s.conn.execute("UPDATE calibrations SET review = replace(review, 'accepted', 'override') WHERE id = ?", [cid])
        s.conn.commit()
        problems = s.verify()
        assert [p["kind"] for p in problems] == ["tampered"] and problems[0]["calibration_id"] == cid


def test_settings_are_remembered(tmp_path):
    with Store(str(tmp_path / "s.db")) as s:
        s.set_settings({"operator": "Ann Lee", "place": "Lab 2, bench 3", "reference": "DMM 34465A #MY123"})
    with Store(str(tmp_path / "s.db")) as s:
        assert s.settings()["place"] == "Lab 2, bench 3"
        s.set_settings({"place": ""})
        assert "place" not in s.settings()


def test_results_screen_saves_a_fail_only_by_decision(tmp_path):
    """The Results screen (real app, pilot): `s` on a FAIL asks; no note, no save; a note
    and ctrl+r store it as rejected; the rejected one is not the reference afterwards."""
    import asyncio

    from station.app import make_app
    from station.screens.results import ResultsScreen
    from tests.test_tui import SIZE, screen_name, text_of, wait_for
    from tests.tui_data import p1_result, seed_history

    db = str(tmp_path / "station.db")
    seed_history(db, "IMU-7", n=1, tolerances={"B": 0.1})  # B may move 0.1 m/s²
    with Store(db) as s:
        previous = s.history("IMU-7")[-1]
    cap, result = p1_result("IMU-7", drift=0.5)  # B moved 0.5 m/s²: FAIL

    async def story():
        app = make_app(db, device_id="IMU-7")
        async with app.run_test(size=SIZE) as pilot:
            await app.push_screen(ResultsScreen(cap, result, None, previous))
            await wait_for(pilot, lambda: app.screen.query_one("#params").row_count > 0)
            assert "FAIL" in text_of(app, "#summary")
            await pilot.press("s")
            await wait_for(pilot, lambda: screen_name(app) == "DecideScreen")
            await pilot.press("ctrl+o")  # no note yet
            await wait_for(pilot, lambda: "Type a reason" in text_of(app, "#error"))
            assert screen_name(app) == "DecideScreen"
            await pilot.press("escape")  # back: nothing saved
            await wait_for(pilot, lambda: screen_name(app) == "ResultsScreen")
            await pilot.press("s")
            await wait_for(pilot, lambda: screen_name(app) == "DecideScreen")
            for ch in "bias jumped":
                await pilot.press("space" if ch == " " else ch)
            await pilot.press("ctrl+r")
            await wait_for(pilot, lambda: screen_name(app) == "ResultsScreen")
            await wait_for(pilot, lambda: app.screen.calibration_id is not None)
            return app.screen.calibration_id, text_of(app, "#saved")

    cal_id, saved = asyncio.run(story())
    assert "REJECTED" in saved
    with Store(db) as s:
        cal = s.calibration(cal_id)
        assert not cal["accepted"] and cal["review"]["note"] == "bias jumped"
        assert cal["review"]["verdict"] == "fail" and cal["review"]["previous_calibration_id"] == previous["id"]
        assert s.reference("IMU-7", "accel-tabletop")["id"] == previous["id"]


@pytest.mark.parametrize("procedure", ["accel-tabletop", "accel-centrifuge", "compass", "gyro-drift", "ldv"])
def test_every_procedure_says_which_calibration_it_saved_on_stderr(tmp_path, procedure):
    """`calibrate --save` names the stored calibration on stderr for every procedure (README
    "Accepting a result"); stdout stays the result alone: with --json one JSON object
    (calibrate.md), whose calibration_id is the same number; without, the text result."""
    db = tmp_path / "s.db"
    path = _sim(tmp_path, procedure, 5)
    r = _save(db, path)
    assert r.returncode == 0, r.stderr
    cal_id = json.loads(r.stdout)["calibration_id"]  # the whole of stdout is the JSON object
    assert r.stderr == f"station: saved calibration {cal_id} as accepted\n"
    with Store(str(db)) as s:
        assert s.calibration(cal_id)["procedure"] == procedure
    second = _sim(tmp_path, procedure, 6)
    cap = read_capture(second)
    cap.meta["device"] = read_capture(path).meta["device"] + "-B"  # another unit: nothing to compare
    write_capture(second, cap)
    r = run_station("calibrate", second, "--save", "--db", db, "--reject", "bench test only")
    assert r.returncode == 3, r.stderr
    assert r.stderr.startswith("station: saved calibration ") and r.stderr.endswith(" as rejected\n")
    new_id = int(r.stderr.split()[3])
    assert new_id != cal_id and f"calibration #{new_id} as rejected" in r.stdout
