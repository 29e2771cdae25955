"""`station diagnose` on P2 tables of averages: the held-out comparison leaves one row out at a time.

The capture is written by the independent generator (benchmarks/diag_generator.py: 19 mountings x
3 speeds in speed order, white noise, no per-row noise columns); the hidden effect's name goes to
the generator only, never to the code under test. A cubic term at 3.5σ of its detection σ passes
its deviance test (score 1.56 against F 1.25) and was refused by the held-out test: the folds of
(mounting + speed rank) mod 10 left out six rows at once, among them several of the high-speed
rows that together fix the cubic's direction, whose held-out prediction was then an
extrapolation (that fold's held-out sum of squares 10 without the cubic, 216 with it, the other
nine folds 549 → 426). Leaving one row out at a time (with the rows the model alone fixes, leverage
above 0.95, out of the comparison as before) asks what the held-out test is for, overfitting,
without that extrapolation.
"""

from __future__ import annotations

from station_run import diagnose_generated


def test_p2_cubic_at_3_5_sigma_that_passes_its_test_is_not_refused_by_a_six_row_fold(tmp_path, capsys):
    res = diagnose_generated(tmp_path, capsys, "accel-centrifuge", "cubic", 784004, k_sigma=3.5)[0]
    assert res["verdict"] == ["cubic"], (res["verdict"], res["candidates"])
