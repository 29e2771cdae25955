"""`station diagnose`: hidden effects found by name, nulls say nothing, confusion and
unresolvable effects reported, quality findings, the diagnose.md JSON shape, bad input.

Hidden-effect captures are written to real files and given to the CLI; the effect's name
is drawn at random inside the test and never passed to the code under test. Sizes are 8σ
of what each capture design resolves (1σ = the size whose fitted signature has Δχ² = 1,
measured by benchmarks/bench_diagnose.py sigma_sizes, docs/benchmarks.md "Diagnose").
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from solvers.simulate import EFFECTS_BY_PROCEDURE, simulate
from station.capture import Capture, write_capture
from station.cli import main

# 8 sigma of what the benchmark design resolves (bench_diagnose.py sigma_sizes × 8).
SIGMA_1 = {
    "accel-tabletop": {
        "temperature_bias": 5.0e-4,
        "time_drift": 5.2e-3,
        "quadratic": 4.3e-5,
        "scale_asymmetry": 4.6e-4,
    },
    "gyro-drift": {"temperature_bias": 1.34e-5, "time_drift": 9.4e-4, "g_sensitivity": 6.3e-6},
    "accel-centrifuge": {
        "temperature_bias": 9.8e-6,
        "time_drift": 8.3e-6,
        "misalignment": 4.2e-6,
        "cubic": 6.7e-10,
        "lever_arm": 4.6e-5,
    },
    "compass": {
        "temperature_bias": 0.049,
        "time_drift": 0.87,
        "mag_accel_misalignment": 1.6e-3,
        "time_varying_hard_iron": 0.019,
    },
    "ldv": {
        "temperature_bias": 7.8e-5,
        "time_drift": 2.2e-3,
        "time_delay": 3.0e-4,
        "lever_arm": 2.1e-3,
        "offset": 2.7e-4,
    },
}
SIZE_8SIGMA = {p: {k: 8.0 * v for k, v in d.items()} for p, d in SIGMA_1.items()}
OPTIONS = {
    "accel-tabletop": {"extra_positions": 12},
    "gyro-drift": {"headings_deg": [0.0, 90.0, 180.0, 270.0]},
    "accel-centrifuge": {},
    "compass": {},
    "ldv": {},
}
TOP_KEYS = {"procedure", "baseline", "candidates", "effects", "extended", "quality", "verdict"}
FIT_KEYS = {"model", "params", "residual_rms", "cv_rms"}
EFFECT_KEYS = {"name", "params", "uncertainty", "cv_rms_before", "cv_rms_after", "gain", "confused_with"}


def _write(tmp_path, sim, name="c.csv") -> str:
    p = tmp_path / name
    write_capture(str(p), Capture(meta=dict(sim.meta), columns=dict(sim.columns)))
    return str(p)


def _diagnose(path, capsys) -> dict:
    rc = main(["diagnose", path, "--json"])
    out = capsys.readouterr().out
    assert rc == 0
    return json.loads(out)


def _row_labels(path) -> list[str]:
    from station.capture import read_capture
    from station.procedures.diagnose import analyse

    _, diag, _ = analyse(read_capture(path))
    return diag.problem.row_labels


def _named(result: dict) -> set[str]:
    return set(result["verdict"])


@pytest.mark.parametrize(
    "procedure,seed",
    [
        ("gyro-drift", 11),
        ("gyro-drift", 12),
        ("accel-tabletop", 21),
        ("accel-tabletop", 22),
        ("accel-centrifuge", 31),
        ("accel-centrifuge", 32),
        ("ldv", 41),
        ("compass", 51),
    ],
)
def test_hidden_effect_is_named(tmp_path, capsys, procedure, seed):
    rng = np.random.default_rng(seed)
    library = [e for e in EFFECTS_BY_PROCEDURE[procedure] if e in SIZE_8SIGMA[procedure]]
    hidden = str(rng.choice(library))
    sim = simulate(procedure, seed=seed, effects={hidden: SIZE_8SIGMA[procedure][hidden]}, **OPTIONS[procedure])
    res = _diagnose(_write(tmp_path, sim), capsys)
    assert hidden in _named(res), (hidden, res["verdict"], res["candidates"])
    eff = {e["name"]: e for e in res["effects"]}
    named = (
        hidden
        if hidden in eff
        else next(e for e in eff.values() if hidden in [c["name"] for c in e["confused_with"]])["name"]
    )
    e = eff[named]
    assert e["cv_rms_after"] < e["cv_rms_before"]
    assert e["gain"] == pytest.approx(1 - e["cv_rms_after"] / e["cv_rms_before"])
    assert res["extended"]["cv_rms"] < res["baseline"]["cv_rms"]


@pytest.mark.parametrize(
    "procedure,seed",
    [("gyro-drift", 101), ("accel-tabletop", 102), ("accel-centrifuge", 103), ("ldv", 104), ("compass", 105)],
)
def test_null_capture_verdict_is_empty(tmp_path, capsys, procedure, seed):
    sim = simulate(procedure, seed=seed, **OPTIONS[procedure])
    res = _diagnose(_write(tmp_path, sim), capsys)
    assert res["verdict"] == []
    assert res["effects"] == []
    assert not any(c["selected"] for c in res["candidates"])


def test_warmup_confuses_temperature_with_time(tmp_path, capsys):
    # one static position, a monotonic warm-up: temperature and time rise together
    sim = simulate("gyro-drift", seed=7, effects={"temperature_bias": 1e-4})
    res = _diagnose(_write(tmp_path, sim), capsys)
    assert {"temperature_bias", "time_drift"} <= _named(res)
    e = res["effects"][0]
    other = {"temperature_bias", "time_drift"} - {e["name"]}
    conf = {c["name"]: c["correlation"] for c in e["confused_with"]}
    assert set(conf) == other
    assert abs(next(iter(conf.values()))) > 0.9


def test_constant_temperature_is_unresolvable_not_absent(tmp_path, capsys):
    sim = simulate("gyro-drift", seed=8)
    sim.columns["temp_c"] = np.full_like(sim.columns["temp_c"], 24.5)
    res = _diagnose(_write(tmp_path, sim), capsys)
    cand = {c["name"]: c for c in res["candidates"]}
    assert cand["temperature_bias"]["resolvable"] is False
    assert "temperature" in cand["temperature_bias"]["reason"]
    assert cand["temperature_bias"]["selected"] is False
    # one orientation: G f is a constant, also unresolvable
    assert cand["g_sensitivity"]["resolvable"] is False


def test_moved_position_and_gap_are_named(tmp_path, capsys):
    sim = simulate("accel-tabletop", seed=9)
    c = {k: np.array(v, copy=True) for k, v in sim.columns.items()}
    pos = c["position"]
    idx = np.flatnonzero(pos == "y_up")
    mid = idx[len(idx) // 2 - 150 : len(idx) // 2 + 150]  # 3 s of handling in the middle
    wob = np.sin(np.linspace(0, 6 * np.pi, len(mid)))
    c["ax"][mid] += 0.08 * wob
    c["az"][mid] += 0.05 * wob
    c["gx"][mid] += 0.4 * wob
    cut = np.flatnonzero(pos == "z_down")
    keep = np.ones(len(pos), bool)
    keep[cut[500:900]] = False  # 4 s of samples lost
    cols = {k: v[keep] for k, v in c.items()}
    path = _write(tmp_path, type(sim)(sim.procedure, sim.meta, cols))
    res = _diagnose(path, capsys)
    kinds = {(q["kind"], q.get("position")) for q in res["quality"]}
    assert ("moved", "y_up") in kinds
    gaps = [q for q in res["quality"] if q["kind"] == "gap"]
    assert len(gaps) == 1 and gaps[0]["duration_s"] == pytest.approx(4.01, abs=0.02)
    assert isinstance(gaps[0]["line"], int)
    # the screen leaves both out of the effect search, and says so
    moved = next(q for q in res["quality"] if q["kind"] == "moved")
    assert moved["screened"] and gaps[0]["screened"] and isinstance(moved["line_stop"], int)
    assert not any(lab.startswith("position y_up ") for lab in _row_labels(path))


def test_json_shape_is_exactly_the_contract(tmp_path, capsys):
    sim = simulate("ldv", seed=3, effects={"offset": 0.01}, duration_s=200.0)
    res = _diagnose(_write(tmp_path, sim), capsys)
    assert set(res) == TOP_KEYS
    assert res["procedure"] == "ldv"
    assert set(res["baseline"]) == FIT_KEYS and set(res["extended"]) == FIT_KEYS
    for c in res["candidates"]:
        assert {"name", "delta_bic", "cv_rms", "selected"} <= set(c)
        if c.get("resolvable") is False:
            assert set(c) == {"name", "delta_bic", "cv_rms", "selected", "resolvable", "reason"}
        else:
            assert set(c) == {"name", "delta_bic", "cv_rms", "selected"}
    assert {c["name"] for c in res["candidates"]} == set(EFFECTS_BY_PROCEDURE["ldv"])
    assert res["verdict"] == ["offset"]
    (e,) = res["effects"]
    assert set(e) == EFFECT_KEYS
    o, so = np.array(e["params"]["o"]), np.array(e["uncertainty"]["o"])
    truth = np.array(sim.truth["effect_blocks"]["o"])
    assert np.all(np.abs(o - truth) < 4 * so + 1e-9), (o, truth, so)  # truth within 4σ per beam


def test_text_report_with_plots(tmp_path, capsys):
    sim = simulate("accel-centrifuge", seed=4, effects={"lever_arm": SIZE_8SIGMA["accel-centrifuge"]["lever_arm"]})
    rc = main(["diagnose", _write(tmp_path, sim)])
    out = capsys.readouterr().out
    assert rc == 0
    assert "verdict" in out and "lever_arm" in out
    assert "measured − simulated" in out


def test_bad_input_one_line_exit_2(tmp_path, capsys):
    p = tmp_path / "bad.csv"
    p.write_text("# station-capture: 1\n# procedure: ldv\nt,vl1\n0,abc\n")
    assert main(["diagnose", str(p), "--json"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bad.csv:" in err[0]
    q = tmp_path / "noproc.csv"
    q.write_text("# station-capture: 1\nt,ax\n0,1\n")
    assert main(["diagnose", str(q)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "procedure" in err[0]


def test_earth_rate_named_when_a_constant_bias_was_fitted(tmp_path, capsys):
    # four headings, no latitude: the baseline is a plain constant bias, and the Earth rate
    # (north and up components, projected with each position's attitude) is what is missing
    sim = simulate(
        "gyro-drift", seed=2, headings_deg=[0.0, 90.0, 180.0, 270.0], duration_s=600.0, gyro_noise_rad_s=0.0005
    )
    sim.meta.pop("latitude_deg")
    res = _diagnose(_write(tmp_path, sim), capsys)
    assert "earth_rate" in res["verdict"]
    eff = {e["name"]: e for e in res["effects"]}
    if "earth_rate" in eff:
        lat = np.radians(float(sim.truth["latitude_deg"]))
        w_ie = 7.292115e-5
        wE, s = np.array(eff["earth_rate"]["params"]["wE"]), np.array(eff["earth_rate"]["uncertainty"]["wE"])
        assert np.all(np.abs(wE - w_ie * np.array([np.cos(lat), np.sin(lat)])) < 5 * s + 2e-6)


def test_row_far_beyond_the_noise_is_named_by_line(tmp_path, capsys):
    sim = simulate("accel-centrifuge", seed=5)
    sim.columns["ay"] = np.array(sim.columns["ay"], copy=True)
    sim.columns["ay"][17] += 2e-3  # 200σ of the table's 1e-5 g noise
    path = _write(tmp_path, sim)
    res = _diagnose(path, capsys)
    out = [q for q in res["quality"] if q["kind"] == "outlier"]
    assert out, res["quality"]
    header = next(i for i, line in enumerate(open(path).read().splitlines(), start=1) if not line.startswith("#"))
    assert out[0]["where"].startswith(f"line {header + 18} ")  # data row 18 (index 17)


@pytest.mark.parametrize("seed", [61, 62])
def test_tabletop_session_gyro_is_diagnosed_beside_the_accelerometer(tmp_path, capsys, seed):
    """A P1 session with a gyro: `station diagnose` diagnoses the gyro's holds too (the result's
    ``gyro`` part, same shape). Whether a g-sensitivity is hidden in the gyro is drawn here."""
    rng = np.random.default_rng(seed)
    hidden = bool(rng.integers(2)) if seed != 62 else not bool(np.random.default_rng(61).integers(2))
    sim = simulate(
        "accel-tabletop",
        seed=seed,
        extra_positions=8,
        hold_s=10,
        move_s=3,
        init_rest_s=20,
        gyro_g_sensitivity=3e-3 if hidden else 0.0,
    )
    res = _diagnose(_write(tmp_path, sim), capsys)
    assert set(res) == TOP_KEYS | {"gyro"}
    gyro = res["gyro"]
    assert set(gyro) == TOP_KEYS and gyro["procedure"] == "gyro-tabletop"
    assert ("g_sensitivity" in gyro["verdict"]) is hidden, gyro["verdict"]
    assert res["verdict"] == []  # the accelerometer has nothing hidden
    cand = {c["name"]: c for c in gyro["candidates"]}
    assert cand["earth_rate"]["resolvable"] is False and "g_sensitivity" in cand["earth_rate"]["reason"]


def test_candidate_with_no_degrees_of_freedom_left_is_unresolvable(tmp_path, capsys):
    """A centrifuge table of 6 mountings at 2 speeds: 12 rows for the baseline's 9 parameters.
    A 3-parameter candidate would fit the rest exactly; it is reported unresolvable with the
    reason, not listed with a large ΔBIC beside an empty verdict."""
    from solvers.simulate import simulate_centrifuge

    sim = simulate_centrifuge(seed=7, n_orientations=6, speeds_rad_s=(2 * np.pi, 4 * np.pi))
    res = _diagnose(_write(tmp_path, sim), capsys)
    assert res["verdict"] == []
    three = [c for c in res["candidates"] if c.get("reason") is None or "degrees of freedom" in c["reason"]]
    assert three and all(c.get("resolvable") is False for c in three), res["candidates"]
    assert all("leave 0 degrees of freedom" in c["reason"] for c in three)


def test_a_reference_imu_record_is_diagnosed_as_mode_a(tmp_path, capsys):
    """P4 with a reference IMU (`gyro_mode: reference`, the TUI's "P4 gyro drift, reference
    IMU"): the diagnosis subtracts the reference, so its baseline is the drift alone; it was
    labelled 'y = ω_E + ε (P4 mode B)', with the Earth rate 'removed: the latitude is known'."""
    sim = simulate("gyro-drift", seed=400777, mode="reference", duration_s=200.0)
    assert sim.meta.get("gyro_mode") == "reference" and "ref_gx" in sim.columns
    d = _diagnose(_write(tmp_path, sim), capsys)
    assert d["baseline"]["model"] == "y = ε (P4 mode A: y = unit − reference)"
    assert "mode B" not in json.dumps(d)
    [earth] = [c for c in d["candidates"] if c["name"] == "earth_rate"]
    assert "reference IMU on the same mount sees it too" in earth["reason"]
    # mode B keeps its own words
    d = _diagnose(_write(tmp_path, simulate("gyro-drift", seed=400778, duration_s=200.0), "b.csv"), capsys)
    assert d["baseline"]["model"] == "y = ω_E + ε (P4 mode B)"


def test_the_residual_test_line_says_its_threshold(tmp_path, capsys):
    """'p = 0.0234 (noise-like)' read as a contradiction at the usual 5 %: the line says the
    station's threshold (p > 0.01) beside its verdict."""
    from solvers.diagnose.engine import WHITE_P

    path = _write(tmp_path, simulate("gyro-drift", seed=400779, duration_s=200.0))
    assert main(["diagnose", path, "--no-plots"]) == 0
    lines = [line for line in capsys.readouterr().out.splitlines() if "residual test" in line]
    assert lines
    for line in lines:
        p = float(re.search(r"p = ([0-9.e+-]+) \(", line).group(1))
        want = f"(noise-like: p > {WHITE_P:g})" if p > WHITE_P else f"(NOT noise-like: p ≤ {WHITE_P:g})"
        assert line.rstrip().endswith(want), line


def test_holds_recorded_alone_are_not_moved_positions(tmp_path, capsys):
    """A bench that records only the holds (no rows while the unit is turned): the stillness
    detector's windows that straddle each gap see two attitudes. That is no motion within a
    hold; with 5 s holds every position but the first read 11 % moving and was named `moved`."""
    sim = simulate("accel-tabletop", seed=4, hold_s=5.0)
    c = {k: np.array(v, copy=True) for k, v in sim.columns.items()}
    keep = c["position"] != ""  # the turns between holds are not recorded
    path = _write(tmp_path, type(sim)(sim.procedure, sim.meta, {k: v[keep] for k, v in c.items()}))
    res = _diagnose(path, capsys)
    assert any(q["kind"] == "gap" for q in res["quality"])  # the turns are gaps in t
    assert not [q for q in res["quality"] if q["kind"] == "moved"], res["quality"]
    # a hold with handling in it is still named (its samples away from the gaps count)
    idx = np.flatnonzero(c["position"] == "y_up")
    mid = idx[len(idx) // 2 - 100 : len(idx) // 2 + 100]
    wob = np.sin(np.linspace(0, 6 * np.pi, len(mid)))
    c["ax"][mid] += 0.08 * wob
    c["gx"][mid] += 0.4 * wob
    path = _write(tmp_path, type(sim)(sim.procedure, sim.meta, {k: v[keep] for k, v in c.items()}))
    res = _diagnose(path, capsys)
    assert [q["position"] for q in res["quality"] if q["kind"] == "moved"] == ["y_up"], res["quality"]
