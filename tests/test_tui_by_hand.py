"""Every procedure completed by hand on the built-in simulated device, through the real
Textual app under its pilot at 80x24: Connect (F5), the operator's keys on the simulated
bench (``p`` places the unit / spins the centrifuge / sweeps the compass / runs the rate
table; ``d`` and ``t`` drive the vehicle), the guide's own checks, Results, ``s`` saves.
No scripted operator: nothing moves unless a key says so.

The source runs on a clock the test advances (device seconds), waiting after each step
until the screen's worker has consumed it, so the runs are the same at any machine load.
"""

from __future__ import annotations

import asyncio
import math

import numpy as np

from db.store import Store
from station.app import make_app
from station.sources import SimSource
from tests.test_tui import SIZE, BenchClock, screen_name, screen_text, wait_for


def caught_up(app, t: float) -> bool:
    g = getattr(app.screen, "guide", None)
    if g is None:
        return False
    st = g.status()
    return math.isfinite(st.t_s) and st.t_s >= t - 0.02  # within a sample or two of the clock


def streaming(app) -> bool:
    """The guided screen is up and its guide still takes samples."""
    g = getattr(app.screen, "guide", None)
    return g is not None and g.phase not in ("done", "aborted")


async def run_until(pilot, app, clock, until, step_s=1.0, max_device_s=900.0):
    """Advance the device clock in steps until ``until()`` (each step consumed first)."""
    while not until():
        assert clock.t_s < max_device_s, f"not done after {max_device_s:g} s of device time:\n{screen_text(app)}"
        clock.t_s += step_s
        try:
            await wait_for(pilot, lambda: caught_up(app, clock.t_s) or not streaming(app), step_s=0.02)
        except AssertionError:
            g = getattr(app.screen, "guide", None)
            raise AssertionError(f"clock {clock.t_s}: {g.status() if g else None}\n{screen_text(app)}") from None


async def connect(pilot, app, screen: str) -> None:
    await pilot.press("f5")
    await wait_for(pilot, lambda: screen_name(app) == screen and getattr(app.screen, "guide", None) is not None)


async def save(pilot, app) -> int:
    await wait_for(pilot, lambda: screen_name(app) == "ResultsScreen")
    await pilot.press("s")
    await wait_for(pilot, lambda: app.screen.calibration_id is not None)
    return app.screen.calibration_id


def saved(db, device, cal_id):
    hist = Store(db).history(device)
    assert [h["id"] for h in hist] == [cal_id]
    return hist[0]


def test_p1_by_hand_the_p_key_places_each_position(tmp_path):
    db = str(tmp_path / "station.db")
    clock = BenchClock()
    src = SimSource(seed=21, clock=clock, max_batch_s=5.0)

    async def story():
        app = make_app(db, device=src, average_s=2.0, settle_s=1.0)
        async with app.run_test(size=SIZE) as pilot:
            await connect(pilot, app, "ProcedureScreen")
            await wait_for(pilot, lambda: "p Place (sim)" in screen_text(app).splitlines()[-1])
            g = app.screen.guide
            first = True
            while g.phase != "done":
                name = g.step.name
                if not (first and name == "x_up"):  # the unit starts on x_up
                    t_press = clock.t_s
                    await pilot.press("p")
                    await wait_for(pilot, lambda: src.imu._move is not None)
                    if name == "y_up":  # looked at: the unit rocks just after it is set down
                        seen = []
                        while clock.t_s < t_press + src.imu.MOVE_S + 1.5:
                            await run_until(pilot, app, clock, lambda t=clock.t_s: clock.t_s >= t + 0.2, step_s=0.2)
                            if clock.t_s > t_press + src.imu.MOVE_S:
                                st = g.status()
                                seen.append((st.is_still, st.phase))
                        assert any(not still for still, _ in seen), seen  # the detector saw it rock
                        assert all(still for still, phase in seen if phase == "average"), seen
                first = False
                await run_until(pilot, app, clock, lambda: g.phase == "done" or g.step.name != name, max_device_s=400)  # noqa: B023
            cal_id = await save(pilot, app)
            return cal_id, g

    cal_id, g = asyncio.run(story())
    rec = saved(db, "SIM-ACC-0021", cal_id)
    assert rec["procedure"] == "accel-tabletop" and rec["n_positions"] == 12
    assert all(s.status == "captured" for s in g.steps)
    truth = src.imu.truth["accel"]
    err = np.abs(np.asarray(rec["params"]["B"]) - truth["B"])
    assert np.all(err < 5 * np.asarray(rec["uncertainty"]["B"]) + 1e-3), (err, rec["uncertainty"]["B"])


def test_p2_by_hand_the_p_key_mounts_and_spins_the_centrifuge(tmp_path):
    db = str(tmp_path / "station.db")
    clock = BenchClock()
    src = SimSource(seed=22, clock=clock, procedure="accel-centrifuge", max_batch_s=5.0)

    async def story():
        app = make_app(db, device=src, average_s=2.0, settle_s=1.0)
        app.session.extra["n_orientations"] = 4  # 12 rows (the exact fit needs more than 9)
        async with app.run_test(size=SIZE) as pilot:
            await connect(pilot, app, "CentrifugeScreen")
            g = app.screen.guide
            text = screen_text(app)
            assert "above ↑turn" in text and "Radius" in text and "m/s^2" in text
            await pilot.press("tab")  # from the step list to the radius field
            await wait_for(pilot, lambda: app.focused is not None and app.focused.id == "radius")
            await pilot.press("end", *["backspace"] * 6, *"abc", "enter")
            await wait_for(pilot, lambda: "radius: 'abc' is not a positive number" in screen_text(app))
            assert g.config.radius_m == 1.0  # nothing changed
            await pilot.press(*["backspace"] * 3, *"1.0", "enter")
            await wait_for(pilot, lambda: app.focused is not None and app.focused.id == "steps")
            assert "not a positive number" not in screen_text(app)
            await run_until(pilot, app, clock, lambda: g.phase == "change", step_s=1.0)  # noise rest, stopped
            assert g.n_captured == 0
            while g.phase != "done":
                k = g.index
                await pilot.press("p")
                await run_until(pilot, app, clock, lambda: g.index != k, step_s=2.0, max_device_s=600)  # noqa: B023
            cal_id = await save(pilot, app)
            return cal_id, g, app.screen.capture

    cal_id, g, capture = asyncio.run(story())
    rec = saved(db, "SIM-CFG-0022", cal_id)
    assert rec["procedure"] == "accel-centrifuge" and rec["n_positions"] == 12
    assert capture.meta["radius_m"] == "1.0" and capture.meta["speed_source"].startswith("set point, confirmed")
    assert all(abs(s.rate_gyro_rad_s / s.speed_rad_s - 1) < 0.02 for s in g.steps)
    truth = src.imu.truth()
    for k in ("S", "b"):
        err = np.abs(np.asarray(rec["params"][k]) - truth[k])
        assert np.all(err <= 5 * np.asarray(rec["uncertainty"][k]) + 1e-9), (k, err)


def test_p3_by_hand_the_p_key_sweeps_the_compass(tmp_path):
    db = str(tmp_path / "station.db")
    clock = BenchClock()
    src = SimSource(seed=23, clock=clock, procedure="compass", max_batch_s=5.0)

    async def story():
        app = make_app(db, device=src)
        async with app.run_test(size=SIZE) as pilot:
            await connect(pilot, app, "CompassScreen")
            g = app.screen.guide
            await run_until(pilot, app, clock, lambda: clock.t_s >= 10, step_s=2.0)
            assert g.coverage < 0.2  # untouched: one direction
            await pilot.press("p")
            await wait_for(pilot, lambda: src.bench("driving") == "sweep")
            await run_until(pilot, app, clock, lambda: g.phase == "done", step_s=2.0, max_device_s=300)
            cal_id = await save(pilot, app)
            return cal_id, g

    cal_id, g = asyncio.run(story())
    assert g.coverage >= 0.8
    rec = saved(db, "SIM-COM-0023", cal_id)
    assert rec["procedure"] == "compass"


def test_p4_reference_imu_by_hand_the_p_key_runs_the_rate_table(tmp_path):
    db = str(tmp_path / "station.db")
    clock = BenchClock()
    src = SimSource(seed=24, clock=clock, procedure="gyro-reference", max_batch_s=5.0)

    async def story():
        app = make_app(db, device=src, average_s=180.0)
        async with app.run_test(size=SIZE) as pilot:
            await connect(pilot, app, "ReferenceScreen")
            g = app.screen.guide
            await pilot.press("p")
            await wait_for(pilot, lambda: src.bench("driving") == "table")
            await run_until(pilot, app, clock, lambda: clock.t_s >= 60, step_s=2.0)
            await wait_for(pilot, lambda: "mounting check: |M|" in screen_text(app) and "OK" in screen_text(app))
            await run_until(pilot, app, clock, lambda: g.phase == "done", step_s=2.0, max_device_s=300)
            cal_id = await save(pilot, app)
            return cal_id

    cal_id = asyncio.run(story())
    rec = saved(db, "SIM-GYR-0024", cal_id)
    assert rec["procedure"] == "gyro-drift" and rec["params"]["mode"] == "reference"
    # the unit's drift minus the reference's own, in P4's frame (x fwd, y up, z right) from
    # the simulated unit's x forward, y left, z up
    truth = np.asarray(src.imu.gyro["eps"]) - src.imu.ref_bias
    truth_p4 = np.array([truth[0], truth[2], -truth[1]])
    err = np.abs(np.asarray(rec["params"]["drift"]) - truth_p4)
    assert np.all(err < 4 * np.asarray(rec["uncertainty"]["drift"])), err


def test_p5_by_hand_d_drives_t_turns_and_the_conditioning_says_when_it_is_enough(tmp_path):
    db = str(tmp_path / "station.db")
    clock = BenchClock()
    src = SimSource(seed=25, clock=clock, procedure="ldv", max_batch_s=5.0)

    async def story():
        app = make_app(db, device=src)
        async with app.run_test(size=SIZE) as pilot:
            await connect(pilot, app, "LdvScreen")
            g = app.screen.guide
            await pilot.press("d")
            await wait_for(pilot, lambda: src.bench("driving") is True)
            await run_until(pilot, app, clock, lambda: clock.t_s >= 40, step_s=2.0)
            await wait_for(pilot, lambda: app.screen.last_status is not None and app.screen.last_status.t_s >= 40)
            assert g.status().verdict == "refused" and "ILL-CONDITIONED" in screen_text(app)
            await pilot.press("t")
            await wait_for(pilot, lambda: src.bench("turning") is True)
            await run_until(pilot, app, clock, lambda: g.phase == "done", step_s=2.0, max_device_s=600)
            st = g.status()
            cal_id = await save(pilot, app)
            return cal_id, st

    cal_id, st = asyncio.run(story())
    assert st.enough and st.kappa < 1e3
    rec = saved(db, "SIM-LDV-0025", cal_id)
    assert rec["procedure"] == "ldv"
    truth = src.imu.truth
    for j in range(3):
        b, u = rec["params"][f"beam{j + 1}"], rec["uncertainty"][f"beam{j + 1}"]
        for key in ("alpha_deg", "beta_deg", "gamma_deg"):
            assert abs(b[key] - truth[key][j]) < 6 * u[key] + 0.05, (j, key, b[key], truth[key][j], u[key])


def _magnetic_heading_deg(imu) -> float:
    """Truth: the heading of the simulated unit's body x from magnetic north (its attitude and
    the field it was given), for comparison with the station's."""
    x_ned = imu.C[:, 0]
    return (math.degrees(math.atan2(x_ned[1], x_ned[0]) - math.atan2(imu.m_ned[1], imu.m_ned[0]))) % 360.0


def _angle_diff_deg(a, b) -> float:
    return abs((a - b + 180.0) % 360.0 - 180.0)


async def _level_and_read(pilot, app, clock, src):
    """`l`: the simulated unit is set down level; once it has settled, the live readout."""
    await pilot.press("l")
    await wait_for(pilot, lambda: src.imu._move is not None)
    await run_until(pilot, app, clock, lambda: src.imu._move is None, step_s=0.5, max_device_s=clock.t_s + 30)
    await run_until(pilot, app, clock, lambda t=clock.t_s: clock.t_s >= t + 1.0, step_s=0.5)
    await wait_for(pilot, lambda: app.screen.last_status is not None and app.screen.last_status.t_s >= clock.t_s - 0.1)
    return app.screen.last_status


def test_p3_live_tilt_and_heading_nominal_front_end_then_the_units_p1_calibration(tmp_path):
    """The simulated compass module's accelerometer reads volts: the live readout converts it
    with the device's declared zero and scale (nominal) or, once the unit has a P1
    calibration in the database, with that. Level reads a tilt near 0; the heading follows
    the sweep; with the P1 calibration and a swept hard iron it agrees with the unit's true
    magnetic heading. The fitted capture carries the front end, so the P3 result has its
    per-position tilt and heading too."""
    from station.calibrate import calibrate_capture
    from station.capture import read_capture
    from station.cli import main

    db = str(tmp_path / "station.db")
    seen = {}

    async def story(label):
        clock = BenchClock()
        src = SimSource(seed=23, clock=clock, procedure="compass", max_batch_s=5.0)
        app = make_app(db, device=src)
        app.session.extra["compass_min_s"] = 900.0  # keep sweeping until the test says
        async with app.run_test(size=SIZE) as pilot:
            await connect(pilot, app, "CompassScreen")
            await wait_for(pilot, lambda: "l Level (sim)" in screen_text(app).splitlines()[-1])
            level = await _level_and_read(pilot, app, clock, src)
            text = screen_text(app)
            heads = []
            await pilot.press("p")
            await wait_for(pilot, lambda: src.bench("driving") == "sweep")
            for _ in range(40):  # 80 s of sweeping: every axis turned over
                await run_until(pilot, app, clock, lambda t=clock.t_s: clock.t_s >= t + 2.0, step_s=1.0)
                heads.append(app.screen.guide.status().heading_deg)
            await pilot.press("p")
            await wait_for(pilot, lambda: src.bench("driving") is None)
            swept = await _level_and_read(pilot, app, clock, src)
            truth = _magnetic_heading_deg(src.imu)
            await pilot.press("f")
            cal_id = await save(pilot, app)
            seen[label] = (level, text, heads, swept, truth, cal_id, app.screen.capture)

    asyncio.run(story("nominal"))
    level, text, heads, swept, truth, _, capture = seen["nominal"]
    assert level.tilt_from == "nominal (data sheet)" and "tilt: nominal (data sheet)" in text
    assert math.hypot(level.pitch_deg, level.roll_deg) < 6.0, level  # the data sheet's zero: a few degrees
    assert "pitch" in text and "heading" in text and " mag" in text
    assert swept.heading_from.startswith("sweep midrange")
    h = np.radians([x for x in heads if math.isfinite(x)])
    assert len(h) >= 30 and np.hypot(np.mean(np.cos(h)), np.mean(np.sin(h))) < 0.7  # headings all round
    assert capture.meta["accel_frontend"] == "nominal (data sheet)" and capture.meta["accel_offset"]

    # the same physical triad calibrated on the level table (station simulate, same seed)
    p1 = tmp_path / "p1.csv"
    assert main(["simulate", "--procedure", "accel-tabletop", "--seed", "23", "--out", str(p1)]) == 0
    cap = read_capture(str(p1))
    with Store(db) as s:
        p1_id = s.save_calibration(calibrate_capture(cap), meta=cap.meta, columns=cap.columns, device_id="SIM-COM-0023")
    asyncio.run(story("p1"))
    level, text, heads, swept, truth, cal_id, capture = seen["p1"]
    assert level.tilt_from.startswith(f"P1 calibration #{p1_id}")
    assert math.hypot(level.pitch_deg, level.roll_deg) < 1.0, level  # level within the placement error
    assert math.hypot(swept.pitch_deg, swept.roll_deg) < 1.0, swept
    assert swept.heading_from.startswith("compass calibration #")  # the nominal run's, saved above
    assert _angle_diff_deg(swept.heading_deg, truth) < 1.5, (swept.heading_deg, truth)
    rec = Store(db).calibration(cal_id)
    assert capture.meta["accel_frontend"].startswith(f"P1 calibration #{p1_id}")
    res = calibrate_capture(capture)
    assert res["accel_frontend"].startswith("P1 calibration") and res["headings"]
    assert not any("no tilt" in w for w in res["warnings"]) and rec["procedure"] == "compass"
