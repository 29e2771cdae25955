"""The two residuals of one P4 capture say what they are over: the Results screen's is per
sample (calibrate's fit), the Diagnose screen's of block means of a stated length (the
diagnosis fits block means). A new user saw "residual 619 °/h" on one and 157.5 °/h on the
other for the same capture, neither saying which."""

from __future__ import annotations

import asyncio
import re

import numpy as np

from solvers.diagnose.problems import gyro_problem
from station.app import make_app
from tests.station_run import run_station
from tests.test_tui import SIZE, history_shown, screen_lines, screen_name, wait_for
from tests.test_tui_import import _open, still_gyro_bin


def _report(app) -> str:
    return str(app.screen.query_one("#report").render())


def test_results_and_diagnose_say_what_their_residual_rms_is_over(tmp_path):
    log = tmp_path / "00000009.BIN"
    still_gyro_bin(log, seed=24)

    async def story():
        app = make_app(str(tmp_path / "s.db"))
        out = {}
        async with app.run_test(size=SIZE) as pilot:
            await _open(pilot, app, log)
            app.screen.query_one("#procedure").value = "gyro-drift"
            await pilot.press("f6")
            await wait_for(pilot, lambda: screen_name(app) == "DiagnoseScreen", timeout_s=60)
            await wait_for(pilot, lambda: "extended" in _report(app), timeout_s=120)
            out["report"] = _report(app)
            await pilot.press("escape")
            await wait_for(pilot, lambda: screen_name(app) == "ImportScreen")
            await pilot.press("f5")
            await wait_for(pilot, lambda: screen_name(app) == "ResultsScreen" and screen_lines(app), timeout_s=120)
            await wait_for(pilot, lambda: " RMS" in "\n".join(screen_lines(app)))
            out["results"] = screen_lines(app)
        return out

    out = asyncio.run(story())
    results = "\n".join(out["results"])
    assert re.search(r"residual \S+ °/h RMS per sample", results), results
    assert all(len(line) <= 80 for line in out["results"])
    # the block the diagnosis averages: max_rows=400 blocks of ceil(10000/400) = 25 samples at 20 ms
    n = 10_000
    per = int(np.ceil(n / 400))
    block_s = per * 0.02
    assert block_s == 0.5
    report = out["report"]
    said = re.findall(r"residual \S+ °/h RMS of (\S+) s block means, held-out", report.replace("\n", " "))
    assert len(said) == 2 and all(float(x) == block_s for x in said), report  # baseline and extended
    assert all(len(line) <= 80 for line in report.splitlines()), report
    # the problem itself says the same length (the label is the code's, not a copy of it)
    t = np.arange(n) * 0.02
    rng = np.random.default_rng(24)
    prob = gyro_problem(t, np.zeros((n, 3)) + rng.normal(0, 1e-3, (n, 3)), None, None, None, np.full(n, "a"))
    assert prob.rows_are == "0.5 s block means"


def test_history_says_what_a_p4_residual_is_over_at_80x24(tmp_path):
    """History's residual column showed a P4 calibration's residual as "412 °/h", the Results
    screen and `calibrate` as "RMS per sample": the same number, one saying what it is over. The
    calibrations are saved by the real CLI (`calibrate --save`, one accepted, one rejected: the
    widest state) from a DataFlash log; History, `station history` and the report say it too."""
    db = tmp_path / "s.db"
    values = []
    for seed, more in ((25, ()), (26, ("--reject", "bench not settled"))):
        log = tmp_path / f"000000{seed}.BIN"
        still_gyro_bin(log, seed=seed)
        run = ("calibrate", log, "--procedure", "gyro-drift", "--device", "GYRO-1", "--save", "--db", db, *more)
        saved = run_station(*run)
        assert saved.returncode == (3 if more else 0), saved.stderr
        said = re.search(r"residual\s+(\S+) °/h RMS per sample", saved.stdout)
        assert said, saved.stdout
        values.append(float(said.group(1)))

    async def story():
        app = make_app(str(db))
        async with app.run_test(size=SIZE) as pilot:
            await pilot.press("f2")
            await history_shown(pilot, app, 2)
            await wait_for(pilot, lambda: "°/h" in "\n".join(screen_lines(app)))
            return screen_lines(app)

    lines = asyncio.run(story())
    shown = "\n".join(lines)
    assert all(len(line) <= 80 for line in lines), shown
    for value, state in zip(values, ("in use", "rejected")):  # calibrate's number, as the column rounds it
        rows = [i for i, line in enumerate(lines) if f"{value:.3g} °/h RMS" in line]
        assert len(rows) == 1, shown
        i = rows[0]  # the row whole: its state beside it, what the RMS is over under it
        assert lines[i].rstrip().endswith(state), lines[i]
        assert lines[i + 1].split("▏")[-1].strip() == "per sample", lines[i + 1]
    hist = run_station("history", "GYRO-1", "--db", db)
    assert hist.returncode == 0 and hist.stdout.count("°/h per sample") == 2, hist.stdout
    report = tmp_path / "r.html"
    assert run_station("report", "1", "--db", db, "-o", report).returncode == 0
    assert "°/h per sample ·" in report.read_text()
