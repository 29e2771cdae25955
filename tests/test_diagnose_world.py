"""`station diagnose` on data it was not tuned to: the published Table 1 (its faulty rows
named by line through the calibration's own screen), a real hand-held compass capture
(structured residuals said first), and an effect the library does not hold (a bias step,
its time drawn here and never passed to the code) named as ``residual:time``."""

from __future__ import annotations

import json

import numpy as np

from solvers.simulate import simulate
from station.capture import Capture, write_capture
from station.cli import main


def _run(capsys, *args) -> tuple[int, str]:
    rc = main(list(args))
    return rc, capsys.readouterr().out


def test_table1_every_faulty_row_named_by_line_and_left_out(shared_data, capsys):
    path = str(shared_data / "wang2021_centrifuge" / "table1.capture.csv")
    rc, out = _run(capsys, "calibrate", path, "--json")
    assert rc == 0
    rejected = {r["line"] for r in json.loads(out)["rejected_rows"]}
    assert len(rejected) == 23
    rc, out = _run(capsys, "diagnose", path, "--json")
    assert rc == 0
    res = json.loads(out)
    screened = [q for q in res["quality"] if q.get("screened")]
    assert {q["line"] for q in screened} == rejected  # one screen: the calibration's
    assert all(q["where"].startswith(f"line {q['line']} ") for q in screened)
    # the effect search ran on the rows that remain: their residual is the table's rounding
    assert res["baseline"]["residual_rms"] < 1e-6
    assert "lever_arm" not in res["verdict"]


def test_structured_residuals_are_said_first(shared_data, capsys):
    path = str(shared_data / "sunsided_marg" / "sunsided_full_sphere.capture.csv")
    rc, out = _run(capsys, "diagnose", path, "--no-plots")
    assert rc == 0
    lines = out.splitlines()
    assert lines[1].startswith("WARNING     residuals not noise-like")
    verdict_at = next(i for i, x in enumerate(lines) if x.startswith("verdict"))
    assert verdict_at > 1
    rc, out = _run(capsys, "diagnose", path, "--json")
    q = next(q for q in json.loads(out)["quality"] if q["kind"] == "residuals_not_white")
    assert (
        q["p_value"] < 0.01 and q["drivers"] and {"driver", "correlation", "explained_by_trend"} <= set(q["drivers"][0])
    )


def test_unlisted_bias_step_is_named_outside_the_library(tmp_path, capsys):
    rng = np.random.default_rng(2024)
    sim = simulate("gyro-drift", seed=77, duration_s=600.0, rate_hz=50.0)
    t = np.asarray(sim.columns["t"], float)
    t_step = float(rng.uniform(0.3, 0.7) * t[-1])  # drawn here, never passed on
    step = rng.normal(size=3)
    step *= 2e-4 / np.linalg.norm(step)  # rad/s: a bias jump (a knock)
    cols = {k: np.array(v, copy=True) for k, v in sim.columns.items()}
    for j, c in enumerate(("gx", "gy", "gz")):
        cols[c] = cols[c] + step[j] * (t >= t_step)
    p = tmp_path / "step.csv"
    write_capture(str(p), Capture(meta=dict(sim.meta), columns=cols))
    rc, out = _run(capsys, "diagnose", str(p), "--json")
    assert rc == 0
    res = json.loads(out)
    assert "residual:time" in res["verdict"], res["verdict"]
    e = next(e for e in res["effects"] if e["name"] == "residual:time")
    assert e["shape"] == "step" and abs(e["params"]["at"] - t_step) < 0.1 * t[-1]
    assert e["gain"] > 0 and set(e["correlation"]) <= {"temperature_bias", "time_drift"}
