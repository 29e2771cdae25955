"""`station noise` on a record that moves: the warning, and no figures. The full-sphere compass
turn (half of it moving) printed a noise density of 1e-151 ± 9.4e+144 rad/s/√Hz beside its
warning, and would have written them into imu.yaml. Now the figures are withheld in every
output (text, JSON, Kalibr's imu.yaml is not written) and the exit status is 1; the real still
records of the same board still give their figures.
"""

from __future__ import annotations

import json

from tests.station_run import run_station

TURN = ("sunsided_marg", "sunsided_full_sphere.capture.csv")
STILL = ("sunsided_marg", "sunsided_unmoved_x_forward.capture.csv")


def test_text_gives_the_warning_and_no_figures(shared_data):
    res = run_station("noise", shared_data.joinpath(*TURN))
    assert res.returncode == 1, (res.returncode, res.stderr)
    assert res.stderr == ""
    assert "of the record moves" in res.stdout and "figures withheld" in res.stdout
    assert "√Hz" not in res.stdout and "Allan deviation [" not in res.stdout  # no table, no plot


def test_json_has_no_figures_and_says_why(shared_data):
    res = run_station("noise", shared_data.joinpath(*TURN), "--json")
    assert res.returncode == 1, res.stderr
    doc = json.loads(res.stdout)
    assert doc["sensors"] == {} and "of the record moves" in doc["withheld"]
    assert any("of the record moves" in w for w in doc["warnings"])


def test_no_kalibr_yaml_is_written_for_a_record_that_moves(shared_data, tmp_path):
    out = tmp_path / "imu.yaml"
    res = run_station("noise", shared_data.joinpath(*TURN), "--format", "kalibr", "--out", out, "--no-plot")
    assert res.returncode == 1, res.stderr
    assert not out.exists() and "figures withheld" in res.stdout and "wrote" not in res.stdout


def test_a_still_record_still_gets_its_figures(shared_data, tmp_path):
    out = tmp_path / "imu.yaml"
    res = run_station("noise", shared_data.joinpath(*STILL), "--format", "kalibr", "--out", out, "--no-plot")
    assert res.returncode == 0, res.stderr
    assert "rad/s/√Hz" in res.stdout and "withheld" not in res.stdout and out.exists()
