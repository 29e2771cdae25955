"""A capture whose ``t`` column is not in seconds (milliseconds, epoch nanoseconds: a converter
that forgot the unit) while its ``sample_rate_hz`` states the real rate: the file contradicts
itself. Where results scale with time they must not come out silently wrong.

Real records from ../shared/data with only ``t`` multiplied (the text, as a foreign converter
would write it): P4's drift error and record length come from ``t``, so ``gyro-drift`` is
refused on the metadata line, as the compass and ``station noise`` refuse it; P1's gyro block
integrates the turns between the holds over ``t`` (1000 times too long gave a gyro residual of
112° RMS with no warning), so it is left uncalibrated with the reason, while the labelled
positions' accelerometer result, which does not depend on ``t``, stands unchanged; without a
``position`` column P1 finds its positions over windows of ``t`` and is refused.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.station_run import assert_one_line_refusal, run_station


def _t_times(src, dst, factor: float) -> int:
    """``src`` with every ``t`` cell multiplied by ``factor``; the line number of sample_rate_hz."""
    lines = src.read_text(encoding="utf-8").splitlines()
    head = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    rate_line = next(i for i, line in enumerate(lines) if line.startswith("# sample_rate_hz:")) + 1
    j = lines[head].split(",").index("t")
    out = lines[: head + 1]
    for line in lines[head + 1 :]:
        cells = line.split(",")
        cells[j] = repr(float(cells[j]) * factor)
        out.append(",".join(cells))
    dst.write_text("\n".join(out) + "\n", encoding="utf-8")
    return rate_line


@pytest.mark.parametrize("command", ["calibrate", "diagnose", "inspect"])
@pytest.mark.parametrize("factor", [1000.0, 1e9])
def test_a_gyro_drift_record_with_t_not_in_seconds_is_refused_on_the_rate_line(shared_data, tmp_path, command, factor):
    path = tmp_path / "still.capture.csv"
    line = _t_times(shared_data / "sunsided_marg" / "sunsided_unmoved_x_forward.capture.csv", path, factor)
    res = run_station(command, path, "--json")
    assert_one_line_refusal(res, f"{path}:{line}:", "sample_rate_hz", "t column", "drift's error")


def test_the_same_gyro_drift_record_in_seconds_still_calibrates(shared_data):
    res = run_station("calibrate", shared_data / "sunsided_marg" / "sunsided_unmoved_x_forward.capture.csv", "--json")
    assert res.returncode == 0, res.stderr


@pytest.mark.parametrize("command", ["calibrate", "diagnose", "inspect"])
def test_a_p1_record_without_labels_with_t_in_ms_is_refused_on_the_rate_line(shared_data, tmp_path, command):
    """imu_tk's real session, no position column: stillness detection found 50 'positions' of
    one sample each and the fit failed with 'values beyond what the model can carry'."""
    path = tmp_path / "xsens.capture.csv"
    line = _t_times(shared_data / "imu_tk_xsens" / "imu_tk_xsens.capture.csv", path, 1000.0)
    res = run_station(command, path, "--json")
    assert_one_line_refusal(res, f"{path}:{line}:", "sample_rate_hz", "windows of t")


def test_a_labelled_p1_session_with_t_in_ms_keeps_its_accelerometer_and_says_why_the_gyro_is_not_calibrated(
    tmp_path,
):
    """A labelled P1 session with gyro columns (the simulator's, labels as a bench writes them):
    the positions come from the labels, the gyro's turns from t."""
    real = tmp_path / "p1.capture.csv"
    made = run_station("simulate", "--procedure", "accel-tabletop", "--seed", "400321", "--out", real)
    assert made.returncode == 0, made.stderr
    path = tmp_path / "p1_ms.capture.csv"
    line = _t_times(real, path, 1000.0)
    good = run_station("calibrate", real, "--json")
    res = run_station("calibrate", path, "--json")
    assert good.returncode == 0 and res.returncode == 0, (good.stderr, res.stderr)
    good, bad = json.loads(good.stdout), json.loads(res.stdout)
    assert "params" in good["gyro"] and good["gyro"]["direction_rms_deg"] < 1.0
    assert "params" not in bad["gyro"]  # it was fitted: 112° RMS, no warning
    assert bad["gyro"]["error"].startswith(f"line {line}: metadata 'sample_rate_hz'")
    assert "integrated over t" in bad["gyro"]["error"]
    # the accelerometer's positions are the same samples: its result does not depend on t's unit
    for block in ("B", "M"):  # equal but for rounding (1e-10 relative: t written times 1000)
        assert np.allclose(bad["params"][block], good["params"][block], rtol=1e-8, atol=1e-8), block
    text = run_station("calibrate", path)
    assert text.returncode == 0 and "gyro       not calibrated: line" in text.stdout
    inspected = json.loads(run_station("inspect", path, "--json").stdout)
    assert any("gyro uncalibrated" in w for w in inspected["warnings"])
