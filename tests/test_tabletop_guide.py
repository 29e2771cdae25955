"""The UI-free P1 guide (station.procedures.tabletop_guide) driven by the simulated bench device."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from solvers.models import accel as accel_model
from solvers.simulate import LiveImu
from station.procedures.tabletop_guide import GuideConfig, P1Guide, position_drawing

RATE_HZ = 100.0
SITE = {"latitude_deg": 39.98, "altitude_m": 52.0}
SIM_NOMINAL = (1.65, 0.0855)  # the simulated triad's data-sheet zero [V] and sensitivity [V per m/s²]


def feed(guide, sim, seconds, follow=True, chunk=10):
    """Run the bench for `seconds` of device time; the operator follows the prompts."""
    events = []
    asked = None
    st = guide.status()
    for _ in range(int(seconds * RATE_HZ / chunk)):
        d = sim.read(chunk)
        st = guide.update(
            d["t_s"],
            np.column_stack([d["ax"], d["ay"], d["az"]]),
            np.column_stack([d["gx"], d["gy"], d["gz"]]),
            d["temp_c"],
        )
        events += guide.take_events()
        if follow and guide.phase == "place" and st.step_name != asked:
            asked = st.step_name
            sim.set_orientation(asked)
        if guide.phase in ("done", "aborted"):
            break
    return st, events


def make(seed=3, average_s=1.0, nominal=SIM_NOMINAL, **kw):
    sim = LiveImu(seed=seed, rate_hz=RATE_HZ, hold_s=1e9)
    guide = P1Guide(
        sample_rate_hz=RATE_HZ,
        accel_unit="V",
        device_id=sim.device_id,
        nominal=nominal,
        config=GuideConfig(average_s=average_s, settle_s=0.5, init_rest_s=1.0),
        site=SITE,
        **kw,
    )
    return sim, guide


def expected_raw(sim, name):
    """The noise-free raw output at the simulated attitude of position `name`."""
    C = sim._targets[name]
    f_b = C.T @ np.array([0.0, 0.0, -sim.g])
    return accel_model.K_matrix(sim.accel) @ f_b + sim.accel["b"]


def test_full_run_captures_every_position_with_the_true_means():
    sim, guide = make()
    st, events = feed(guide, sim, 150)
    assert guide.phase == "done", st.message
    assert [e for e in events if e[0] == "captured"] == [("captured", s.name) for s in guide.steps]
    assert ("done", "") in events
    for s in guide.steps:
        assert s.status == "captured" and s.n >= 100  # 1 s at 100 Hz
        # white noise 0.01 m/s² x ~0.0855 V/(m/s²) per sample: 5 sigma of the mean
        tol_v = 5 * np.asarray(s.std) / math.sqrt(s.n)
        assert np.all(np.abs(np.asarray(s.mean) - expected_raw(sim, s.name)) < tol_v), s.name
        assert 0.0005 < s.std[0] < 0.0013  # the per-sample noise, ~0.00086 V


def test_wrong_face_up_is_flagged_and_never_captured():
    sim, guide = make()
    feed(guide, sim, 1.5, follow=False)  # noise floor at the start position (x_up)
    assert guide.step.name == "x_up"
    sim.set_orientation("x_down")  # the operator turns it the wrong way
    st, events = feed(guide, sim, 8, follow=False)
    assert st.wrong_face and st.angle_deg > 170
    assert st.phase == "place" and st.message == "Upside down: turn the unit over"
    assert not [e for e in events if e[0] == "captured"]
    sim.set_orientation("x_up")
    st, events = feed(guide, sim, 8, follow=False)
    assert ("captured", "x_up") in events


def test_a_quarter_turn_is_not_called_upside_down():
    """A side face up (90° from x_up, give or take the placement) is a quarter turn: the prompt
    says how far off it is and which face to put up, not 'turn the unit over' (which said so at
    90.6°)."""
    sim, guide = make()
    feed(guide, sim, 1.5, follow=False)
    sim.set_orientation("y_up")
    st, events = feed(guide, sim, 8, follow=False)
    assert 80 < st.angle_deg < 100 and st.phase == "place", st.angle_deg
    assert "turn the unit over" not in st.message and f"{st.angle_deg:.0f}°" in st.message, st.message
    assert not [e for e in events if e[0] == "captured"]


def test_three_eighths_of_a_turn_is_not_called_a_quarter_turn():
    """Anything between 45° and 135° off was called 'a quarter turn' (seen at 134°): only near 90°."""
    from station.procedures.tabletop_guide import wrong_face_message

    assert "quarter turn" in wrong_face_message(91.0)
    for angle in (55.0, 125.0, 134.0):
        message = wrong_face_message(angle)
        assert "quarter turn" not in message and f"{angle:.0f}° off" in message, message
    assert wrong_face_message(150.0).startswith("Upside down")


def test_a_tilted_placement_is_not_in_position():
    sim, guide = make()
    feed(guide, sim, 1.5, follow=False)
    sim.set_orientation("xy_45")  # 45° off x_up: still, right face, wrong position
    st, events = feed(guide, sim, 6, follow=False)
    # 45° apart, give or take the placements (within 3° on the 45° block, 1° flat) and the
    # nominal (uncalibrated) zero and scale the angle is read with
    assert 38 < st.angle_deg < 52 and not st.wrong_face and not st.in_position
    assert st.phase == "place" and not [e for e in events if e[0] == "captured"]


def test_moving_during_the_average_restarts_it():
    sim, guide = make(average_s=4.0)
    st, _ = feed(guide, sim, 4.0, follow=False)
    assert st.phase == "average" and st.countdown_s < 4.0
    sim.set_orientation("x_up")  # already there: jiggle by moving away and back
    sim.set_orientation("y_up")
    st, events = feed(guide, sim, 1.0, follow=False)
    assert any(e[0] == "restarted" for e in events)
    assert st.phase in ("place", "settle") and not st.is_still


def test_countdown_runs_down_in_device_time():
    sim, guide = make(average_s=3.0)
    seen = []
    for _ in range(60):
        st, _ = feed(guide, sim, 0.1, follow=False)
        if st.phase == "average":
            seen.append((st.t_s, st.countdown_s, st.progress))
    assert len(seen) > 10
    (t0, c0, p0), (t1, c1, p1) = seen[0], seen[-1]
    assert c0 - c1 == pytest.approx(t1 - t0, abs=0.11)
    assert p1 > p0


def test_skip_redo_abort():
    sim, guide = make()
    feed(guide, sim, 1.5, follow=False)
    guide.skip()
    assert guide.steps[0].status == "skipped" and guide.step.name == "x_down"
    st, events = feed(guide, sim, 12)
    assert ("captured", "x_down") in events
    guide.redo(1)
    assert guide.steps[1].status == "pending" and guide.step.name == "x_down" and guide.phase == "place"
    guide.abort()
    assert guide.phase == "aborted" and ("aborted", "") in guide.take_events()
    st = guide.update([99.0], [[1.65, 1.65, 2.5]])  # ignored once aborted
    assert st.phase == "aborted"


def test_skipped_steps_come_back_after_the_rest():
    sim, guide = make()
    feed(guide, sim, 1.5, follow=False)
    guide.skip()
    st, events = feed(guide, sim, 200)
    captured = [e[1] for e in events if e[0] == "captured"]
    assert captured[0] == "x_down" and guide.phase == "done"
    assert guide.steps[0].status == "skipped" and "x_up" not in captured
    assert guide.capture(rotations=False).n_rows == 11
    assert len(set(guide.capture().columns["position"]) - {""}) == 11


def test_resume_from_the_state_file(tmp_path):
    path = str(tmp_path / "resume.json")
    sim, guide = make(state_path=path)
    st, events = feed(guide, sim, 13)
    done = [e[1] for e in events if e[0] == "captured"]
    assert len(done) >= 2
    state = json.loads(open(path).read())
    assert [s["status"] for s in state["steps"]][: len(done)] == ["captured"] * len(done)
    # a new session (new process, same bench) picks up at the next position
    resumed = P1Guide.load(path, nominal=SIM_NOMINAL)
    assert resumed.n_captured == len(done)
    assert resumed.step.name == guide.steps[len(done)].name
    assert resumed.phase == "noise"  # measures the noise again before anything else
    assert resumed.steps[0].mean == guide.steps[0].mean
    sim.set_orientation(resumed.step.name)
    st, events = feed(resumed, sim, 150)
    assert resumed.phase == "done" and resumed.n_captured == 12


def _damaged(state: dict, how: str) -> dict:
    state = json.loads(json.dumps(state))
    first = state["steps"][0]
    if how == "index":
        state["index"] = 999
    elif how == "no direction":
        del first["direction"]
    elif how == "mean text":
        first["mean"] = "abc"
    elif how == "mean short":
        first["mean"] = [1.0, 2.0]
    elif how == "mean nan":
        first["mean"] = [1.0, float("nan"), 2.0]
    elif how == "status":
        first["status"] = "eaten"
    elif how == "extra key":
        first["colour"] = "red"
    elif how == "config":
        state["config"]["average_s"] = -1
    elif how == "rate":
        state["sample_rate_hz"] = "fast"
    elif how == "steps":
        state["steps"] = {"x_up": first}
    return state


@pytest.mark.parametrize(
    ("how", "says"),
    [
        ("index", "index 999"),
        ("no direction", "step 1"),
        ("mean text", "step 1"),
        ("mean short", "step 1"),
        ("mean nan", "step 1"),
        ("status", "step 1"),
        ("extra key", "step 1"),
        ("config", "config"),
        ("rate", "sample_rate_hz"),
        ("steps", "steps"),
    ],
)
def test_a_damaged_resume_file_is_refused_naming_what_is_wrong(tmp_path, how, says):
    """A resume file edited or damaged (an index beyond the steps crashed the TUI on the first
    live update; a text mean reached the fit; a missing key surfaced as the bare "'direction'")
    is refused as a whole with one ValueError naming the field, so the operator starts anew."""
    path = str(tmp_path / "resume.json")
    sim, guide = make(state_path=path)
    feed(guide, sim, 13)
    state = json.loads(open(path).read())
    P1Guide.from_state(state, nominal=SIM_NOMINAL)  # the file as written resumes
    with pytest.raises(ValueError, match="resume state") as err:
        P1Guide.from_state(_damaged(state, how), nominal=SIM_NOMINAL)
    assert says in str(err.value)


def test_orientation_is_learned_without_a_nominal_scale():
    sim = LiveImu(seed=5, rate_hz=RATE_HZ, hold_s=1e9)
    guide = P1Guide(
        sample_rate_hz=RATE_HZ,
        accel_unit="counts",
        device_id="X",
        config=GuideConfig(average_s=1.0, settle_s=0.5, init_rest_s=1.0),
        site=SITE,
    )
    st, _ = feed(guide, sim, 1.5)
    assert math.isnan(st.angle_deg)  # nothing known yet: the operator is trusted
    st, events = feed(guide, sim, 35)
    captured = [e[1] for e in events if e[0] == "captured"]
    assert {"x_up", "x_down", "y_up", "y_down", "z_up", "z_down"} <= set(captured)
    # after the six axis positions the model knows all axes: |f| is g within 1 %
    assert st.norm_mps2 == pytest.approx(guide.g_mps2, rel=0.01)


def test_previous_calibration_is_the_model_so_far():
    sim, _ = make()
    B, M = accel_model.forward_to_p1(sim.accel)
    guide = P1Guide(
        sample_rate_hz=RATE_HZ,
        accel_unit="V",
        config=GuideConfig(average_s=1.0, init_rest_s=1.0),
        previous={"params": {"B": B.tolist(), "M": M.tolist()}},
        site=SITE,
    )
    st, _ = feed(guide, sim, 2.0, follow=False)
    assert st.norm_mps2 == pytest.approx(guide.g_mps2, abs=0.02)  # noise ~0.01 m/s² per 0.1 s mean
    assert st.angle_deg < 2.0  # placement error up to 1°


def test_capture_table_round_trips_through_a_file(tmp_path):
    from station.capture import read_capture, write_capture

    sim, guide = make()
    feed(guide, sim, 150)
    cap = guide.capture(rotations=False)
    assert cap.procedure == "accel-tabletop" and not cap.is_time_series and cap.n_rows == 12
    assert cap.meta["device"] == sim.device_id and cap.meta["accel_unit"] == "V"
    write_capture(str(tmp_path / "p1.csv"), cap)
    back = read_capture(str(tmp_path / "p1.csv"))
    assert list(back.columns["position"]) == list(cap.columns["position"])
    np.testing.assert_array_equal(back.columns["ax"], cap.columns["ax"])


def test_p1_fit_of_the_guided_capture_recovers_the_truth():
    calibrate = pytest.importorskip("station.procedures.tabletop", reason="P1 solver not in this checkout yet")
    from station.calibrate import calibrate_capture

    sim, guide = make(average_s=2.0)
    feed(guide, sim, 200)
    result = calibrate_capture(guide.capture())
    B, M = accel_model.forward_to_p1(sim.accel)
    # |B + M V| = g fixes B, M up to a rotation; compare the gauge-free M^T M and norm residuals
    Mf, Bf = np.asarray(result["params"]["M"]), np.asarray(result["params"]["B"])
    # averages of 200 samples: ~7e-4 m/s² each, i.e. ~1e-4 relative; M^T M ~ 130: atol 0.1
    np.testing.assert_allclose(Mf.T @ Mf, M.T @ M, atol=0.1)
    # the fitted model maps every noise-free position reading onto a sphere of radius g
    for s in guide.steps:
        assert np.linalg.norm(Bf + Mf @ expected_raw(sim, s.name)) == pytest.approx(guide.g_mps2, abs=0.01)
    assert calibrate is not None


@pytest.mark.parametrize("bad", [{"average_s": 0}, {"settle_s": -1}, {"angle_tol_deg": float("nan")}])
def test_bad_config_is_refused(bad):
    with pytest.raises(ValueError):
        GuideConfig(**bad)


def test_drawings_label_the_up_face():
    assert "-X" in "\n".join(position_drawing([-1, 0, 0]))
    assert "+Z" in "\n".join(position_drawing([0, 0, 1]))
    art = "\n".join(position_drawing([math.sqrt(0.5), math.sqrt(0.5), 0]))
    assert "+X" in art and "+Y" in art and "Z level" in art
    assert all(len(line) <= 30 for d in ([1, 0, 0], [0, -0.7, 0.7]) for line in position_drawing(d))


def test_procedure_logic_does_not_load_textual():
    """The guides, the review helpers, the noise report, the shared detectors, the device
    layer's live detectors and the sources are UI-free (checked in a fresh process)."""
    import subprocess
    import sys

    code = (
        "import sys, station.procedures.tabletop_guide, station.procedures.compass_guide, "
        "station.procedures.gyrodrift_guide, station.procedures.centrifuge_guide, station.procedures.noise, "
        "station.procedures.review, station.sources, solvers.detectors, station.device.live; "
        "print('textual' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"


def test_the_session_records_the_turns_and_calibrates_both_triads(tmp_path):
    """With the gyro streamed, the guide's capture is the whole session (a position label on each
    average): one tabletop session gives the accelerometer and the gyro calibration, and the
    capture round-trips through a file."""
    from station.calibrate import calibrate_capture
    from station.capture import read_capture, write_capture

    sim, guide = make(average_s=2.0, gyro_unit="rad/s")
    feed(guide, sim, 250)
    assert guide.phase == "done"
    cap = guide.capture()
    assert cap.is_time_series and cap.meta["gyro_unit"] == "rad/s"
    assert [p for p in dict.fromkeys(cap.columns["position"]) if p] == [s.name for s in guide.steps]
    write_capture(str(tmp_path / "p1.csv"), cap)
    result = calibrate_capture(read_capture(str(tmp_path / "p1.csv")))
    gb = result["gyro"]
    assert gb["n_holds"] == 12 and gb["n_rotations"] == 11
    truth = sim.truth["gyro"]
    z = (np.asarray(gb["params"]["eps"]) - np.asarray(truth["eps"])) / np.asarray(gb["uncertainty"]["eps"])
    assert np.all(np.abs(z) < 4)
    np.testing.assert_allclose(np.diag(gb["params"]["K"]), np.diag(truth.get("K", np.eye(3))), atol=0.02)
    assert gb["direction_rms_deg"] < 0.5
