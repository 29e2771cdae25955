"""What a bench engineer new to the station met on the command line: slightly wrong
arguments answered with one clear line (the real CLI, real files)."""

from __future__ import annotations

from tests.station_run import assert_one_line_refusal, run_station


def test_simulate_names_the_options_of_the_procedure_for_a_mistyped_one(tmp_path):
    """`--option mag_noise=1` (for mag_noise_uT) said "simulate_compass() got an unexpected
    keyword argument 'mag_noise'": Python's words for the simulator's function, not which
    options there are. Now it names the option and the procedure's options."""
    out = tmp_path / "c.csv"
    res = run_station("simulate", "--procedure", "compass", "--out", out, "--option", "mag_noise=1")
    assert_one_line_refusal(res, "--option mag_noise", "mag_noise_uT", "n_orientations")
    assert "keyword argument" not in res.stderr and "simulate_compass" not in res.stderr
    assert not out.exists()
    # the options not settable from the command line are not offered
    assert "site" not in res.stderr.split("mag_noise_uT", 1)[1]
