"""The UI-free P2 centrifuge guide (station.procedures.centrifuge_guide): the live path on
the simulated centrifuge, the manual path (typed averages) and its refusals, the step
list's skip / redo / select / abort, and the table of averages calibrate_capture takes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from solvers.simulate import simulate_centrifuge
from station.calibrate import calibrate_capture
from station.procedures.centrifuge_guide import (
    MIN_FIT_ROWS,
    CentrifugeConfig,
    CentrifugeGuide,
    CentrifugeOperator,
    ManualEntryError,
    centrifuge_steps,
    parse_manual,
)
from station.sources import SimSource

SPEEDS = (2 * math.pi, 4 * math.pi, 6 * math.pi)


def test_default_steps_are_the_papers_20_orientations_at_3_speeds():
    steps = centrifuge_steps(CentrifugeConfig())
    assert len(steps) == 60
    assert [(s.orientation, round(s.speed_rad_s, 6)) for s in steps[:4]] == [
        (1, round(2 * math.pi, 6)),
        (1, round(4 * math.pi, 6)),
        (1, round(6 * math.pi, 6)),
        (2, round(2 * math.pi, 6)),
    ]
    assert steps[0].prompt.startswith("Mount in orientation 1, spin at 6.28 rad/s (1 rev/s)")
    steps = centrifuge_steps(CentrifugeConfig(speeds_rad_s=[5.0], n_orientations=3))
    assert [s.label for s in steps] == [" 1 @  5.00 rad/s", " 2 @  5.00 rad/s", " 3 @  5.00 rad/s"]


@pytest.mark.parametrize(
    "fields, message",
    [
        (("1.2", "abc", "0.3", "6.28"), "ay: 'abc' is not a number"),
        (("", "0", "0", "6.28"), "ax: empty"),
        (("1,5", "0", "0", "6.28"), "ax: '1,5' is not a number"),
        (("nan", "0", "0", "6.28"), "ax: 'nan' is not a number"),
        (("1_0", "0", "0", "6.28"), "ax: '1_0' is not a number"),
        (("0x10", "0", "0", "6.28"), "ax: '0x10' is not a number"),
        (("1e999", "0", "0", "6.28"), "ax: '1e999' is out of range"),
        (("1", "0", "0", "0"), "speed: 0 rad/s; the centrifuge speed must be > 0"),
        (("1", "0", "0", "-6.28"), "speed must be > 0"),
        (("1", "0", "0", "fast"), "speed: 'fast' is not a number"),
    ],
)
def test_bad_manual_entries_are_refused_with_one_message(fields, message):
    with pytest.raises(ManualEntryError) as info:
        parse_manual(*fields)
    assert message in str(info.value) and "\n" not in str(info.value)


def test_good_manual_entries_parse():
    assert parse_manual(" 1.5", "-0.25e-1", ".5", "12.566") == (1.5, -0.025, 0.5, 12.566)
    assert parse_manual("+2", "3.", "-0", "1E1") == (2.0, 3.0, 0.0, 10.0)


def test_a_bad_entry_changes_nothing():
    g = CentrifugeGuide(sample_rate_hz=100, units={"accel_unit": "g"})
    with pytest.raises(ManualEntryError):
        g.enter_manual("1", "2", "x", "6.28")
    assert g.index == 0 and g.steps[0].status == "pending" and g.n_captured == 0 and not g.take_events()


def test_typed_averages_give_the_same_calibration_as_the_file():
    """Two routes, one answer: the 60 rows of simulate_centrifuge typed in by hand (as
    repr strings) become a capture whose calibration equals that of the simulator's own."""
    sim = simulate_centrifuge(seed=4)
    cols = sim.columns
    g = CentrifugeGuide(
        sample_rate_hz=100,
        units={"accel_unit": "g"},
        device_id=sim.meta["device"],
        config=CentrifugeConfig(radius_m=float(sim.meta["radius_m"]), g_mps2=float(sim.meta["g_mps2"])),
    )
    for s in list(g.steps):
        assert g.step is s  # the guide walks the list in order
        j = SPEEDS.index(min(SPEEDS, key=lambda w: abs(w - s.speed_rad_s))) * 20 + s.orientation - 1
        assert cols["position"][j] == str(s.orientation) and cols["speed_rad_s"][j] == pytest.approx(s.speed_rad_s)
        g.enter_manual(*(repr(float(cols[c][j])) for c in ("ax", "ay", "az", "speed_rad_s")))
    assert g.phase == "done" and g.n_captured == 60 and ("done", "") in g.take_events()
    cap = g.capture()
    assert cap.procedure == "accel-centrifuge" and cap.meta["manual_rows"] == "60" and "n" not in cap.columns
    assert cap.meta["radius_m"] == "1.0" and cap.meta["accel_unit"] == "g"
    from station.capture import Capture

    ref = calibrate_capture(Capture(meta=dict(sim.meta), columns=dict(cols)))
    got = calibrate_capture(cap)
    for k in ("S", "b", "D"):
        np.testing.assert_allclose(got["params"][k], ref["params"][k], rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(got["params"]["S"], sim.truth["S"], rtol=1e-4)  # noise 1e-5 g


def run(now, src, guide, seconds, operator=None, dt=0.1):
    t_end = now[0] + seconds
    events = []
    while now[0] < t_end and guide.phase not in ("done", "aborted"):
        now[0] += dt
        b = src.drain()
        if b is None:
            continue
        st = guide.update(b.t_s, b.accel, b.gyro, b.temp_c)
        if operator is not None:
            operator.step(guide, st.t_s)
        events += guide.take_events()
    return events


def live(n_orientations=12, average_s=2.0, seed=1):
    now = [0.0]
    src = SimSource(seed=seed, procedure="accel-centrifuge", clock=lambda: now[0]).start()
    guide = CentrifugeGuide(
        sample_rate_hz=src.rate_hz,
        units=src.units,
        device_id=src.device_id,
        config=CentrifugeConfig(n_orientations=n_orientations, average_s=average_s, settle_s=1.0),
    )
    return now, src, guide


def test_live_averages_at_speed_recover_the_simulated_triad():
    """The scripted operator mounts and spins the simulated centrifuge as asked; each row is
    averaged once the output is steady; the fit recovers S, b, D within 4 sigma."""
    now, src, guide = live()
    events = run(now, src, guide, 900, CentrifugeOperator(src.place))
    assert guide.phase == "done" and guide.n_captured == 36, guide.status().message
    assert not [e for e in events if e[0] == "restarted"]
    rows = [s for s in guide.steps if s.how == "live"]
    assert len(rows) == 36 and all(s.n >= 200 for s in rows)  # >= 2 s at 100 Hz
    cap = guide.capture()
    assert {"n", "ax_std", "ay_std", "az_std"} <= set(cap.columns)
    result = calibrate_capture(cap)
    truth = src.imu.truth()
    for k in ("S", "b", "D"):
        err = np.abs(np.asarray(result["params"][k]) - truth[k])
        sig = np.asarray(result["uncertainty"][k])
        assert np.all(err <= 4 * sig + 1e-12), (k, err, sig)


def test_a_steady_run_is_not_taken_twice_and_a_changing_output_restarts_nothing_captured():
    now, src, guide = live(n_orientations=2)
    run(now, src, guide, 6)  # the stopped centrifuge: the noise rest, then no row from it
    assert guide.phase == "change" and guide.n_captured == 0
    src.place("1@" + repr(2 * math.pi))
    run(now, src, guide, 8)
    assert guide.steps[0].status == "captured" and guide.index == 1
    run(now, src, guide, 10)  # nobody changes the speed: the next step waits
    assert guide.phase == "change" and guide.steps[1].status == "pending"
    assert "waiting for the change" in guide.status().message
    src.place("1@" + repr(4 * math.pi))
    run(now, src, guide, 8)
    assert guide.steps[1].status == "captured"
    # the second row is at the faster speed: a larger output (S > 0, |f|² = A² + 1)
    assert np.linalg.norm(guide.steps[1].values) > np.linalg.norm(guide.steps[0].values)


def test_skip_redo_select_abort_and_finish():
    g = CentrifugeGuide(
        sample_rate_hz=100, units={"accel_unit": "g"}, config=CentrifugeConfig(n_orientations=4)
    )  # 12 steps
    g.enter_manual("1", "0", "0", "6.3")
    g.skip()
    assert [s.status for s in g.steps[:3]] == ["captured", "skipped", "pending"] and g.index == 2
    g.redo()  # the last one before the current: the skipped step
    assert g.index == 1 and g.steps[1].status == "pending"
    g.select(0)  # a captured step: redo it
    assert g.index == 0 and g.steps[0].status == "pending" and g.n_captured == 0
    assert not g.finish()  # fewer than MIN_FIT_ROWS
    for k in range(MIN_FIT_ROWS):
        g.enter_manual(str(1 + k), "0", "0", "6.3")
    assert g.can_fit and g.finish() and g.phase == "done"
    g.abort()
    assert g.phase == "aborted"
    with pytest.raises(ManualEntryError, match="run is over"):
        g.enter_manual("1", "0", "0", "6.3")


@pytest.mark.parametrize(
    "bad",
    [
        {"speeds_rad_s": []},
        {"speeds_rad_s": [0.0]},
        {"n_orientations": 0},
        {"radius_m": -1},
        {"average_s": float("nan")},
    ],
)
def test_bad_config_is_refused(bad):
    with pytest.raises(ValueError):
        CentrifugeConfig(**bad)


def test_a_stopped_centrifuge_is_never_a_row_even_when_the_operator_picks_the_step():
    """The bug seen at the bench: Enter on a step while the centrifuge stood still stored a
    row with the asked speed (6.28 rad/s) while the table turned at 0.001 rad/s. A row now
    waits until the gyro measures the asked speed, and stores what it measured."""
    now, src, guide = live(n_orientations=2)
    run(now, src, guide, 4)  # the noise rest, centrifuge stopped
    guide.select(0)  # the operator picks step 1: steady output, but the table does not turn
    run(now, src, guide, 10)
    st = guide.status()
    assert guide.n_captured == 0 and st.phase == "place" and not st.at_speed
    assert st.table_rate_rad_s < 0.01 and "not at speed" in st.message
    src.place("1@" + repr(6.0))  # the wrong speed: steady, but 4.5 % slow
    run(now, src, guide, 10)
    assert guide.n_captured == 0 and not guide.status().at_speed
    src.place("1@" + repr(2 * math.pi))
    run(now, src, guide, 10)
    s = guide.steps[0]
    assert s.status == "captured" and s.how == "live"
    # the confirmed set point is the row's speed; the gyro's mean rides along (1e-3 rad/s
    # noise per sample, ~200 samples: 1e-4 rad/s)
    assert s.speed_measured_rad_s == s.speed_rad_s and abs(s.rate_gyro_rad_s - s.speed_rad_s) < 5e-4
    cap = guide.capture()
    assert cap.columns["rate_gyro_rad_s"][0] == s.rate_gyro_rad_s
    assert cap.meta["speed_source"].startswith("set point, confirmed by the gyro on the table within 2 %")


def test_rows_that_disagree_are_named_as_soon_as_they_are_in():
    """Typed rows of the simulator's own table; one typed at a speed off the asked one and
    one with a lost minus sign: each is named by the event that follows its entry (the
    model's robust screen runs from MIN_FIT_ROWS rows on; with 9 coefficients it needs
    a few dozen rows to set one apart)."""
    sim = simulate_centrifuge(seed=4)
    cols = sim.columns
    g = CentrifugeGuide(
        sample_rate_hz=100,
        units={"accel_unit": "g"},
        config=CentrifugeConfig(radius_m=float(sim.meta["radius_m"]), g_mps2=float(sim.meta["g_mps2"])),
    )
    named = []
    for k, s in enumerate(list(g.steps)[:36]):
        j = SPEEDS.index(min(SPEEDS, key=lambda w: abs(w - s.speed_rad_s))) * 20 + s.orientation - 1
        vals = [repr(float(cols[c][j])) for c in ("ax", "ay", "az", "speed_rad_s")]
        if k == 31:
            vals[1] = repr(-float(cols["ay"][j]))  # a lost minus sign
        if k == 3:
            vals[3] = repr(float(cols["speed_rad_s"][j]) * 1.05)  # the tachometer read 5 % high
        g.enter_manual(*vals)
        named.append([d for kind, d in g.take_events() if kind == "disagree"])
        if k == 31:
            assert g.status().message.startswith("Entered 11 @ 12.57 rad/s: DISAGREES (|f| off the model")
    assert named[3] == ["2 @  6.28 rad/s: speed 6.597 rad/s, asked 6.283"]
    assert len(named[31]) == 1 and named[31][0].startswith("11 @ 12.57 rad/s: |f| off the model")
    assert "lost minus sign" in named[31][0]
    assert all(not n for k, n in enumerate(named) if k not in (3, 31))
    assert set(g.disagreeing) == {3, 31}
    assert g.capture().meta["rows_disagreeing"] == "2 @  6.28 rad/s, 11 @ 12.57 rad/s"
    g.redo(31)  # redone: no longer named
    assert set(g.disagreeing) == {3}


def test_radius_and_local_g_are_checked_and_stored():
    from station.procedures.centrifuge_guide import parse_positive

    assert parse_positive(" 0.85 ", "radius") == 0.85
    for bad in ("", "-1", "0", "abc", "1e999"):
        with pytest.raises(ManualEntryError, match="not a positive number"):
            parse_positive(bad, "radius")
    g = CentrifugeGuide(
        sample_rate_hz=100, units={"accel_unit": "g"}, config=CentrifugeConfig(radius_m=0.85, g_mps2=9.80156)
    )
    g.enter_manual("1", "0", "0", "6.3")
    cap = g.capture()
    assert cap.meta["radius_m"] == "0.85" and cap.meta["g_mps2"] == "9.80156"
    assert cap.meta["speed_source"] == "typed by the operator"


def test_the_drawing_of_a_mounting_matches_its_attitude():
    """Each mounting's drawing lists the triad's axes in the table frame (out, turn, up):
    the rows of the attitude the simulated centrifuge uses for that orientation."""
    from solvers.simulate import centrifuge_orientations
    from station.procedures.centrifuge_guide import mounting_drawing

    for k in (1, 7, 20):
        lines = mounting_drawing(k)
        C_t_b = centrifuge_orientations(20)[k - 1]
        for a, name in enumerate("xyz"):
            row = lines[1 + a][24:]  # the table beside the two views
            assert row.split()[0] == name
            nums = [float(x) for x in row.split()[1:]]
            np.testing.assert_allclose(nums, C_t_b[:, a], atol=0.006)
        assert len(lines) == 5 and all(len(line) <= 56 for line in lines)  # the P2 screen at 80x24
        assert "o" in lines[2] and "→" in lines[2]
