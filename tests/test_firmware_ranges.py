"""PX4 exports refuse scale factors outside the range PX4 documents for them (one line, exit
status 2, nothing written); before, only "positive" was checked, so a composed scale of 3.2 went
into a parameter file the ground station flags and the firmware would apply as is.

The range, as PX4 documents it: PX4/PX4-Autopilot, src/modules/sensors/module.yaml (commit
5cda32d5565b9047eb792056cb8c2aaf6da5c2a3), CAL_ACC${i}_{X,Y,Z}SCALE and
CAL_MAG${i}_{X,Y,Z}SCALE: ``min: 0.1``, ``max: 3.0`` (the gyro has offsets only; ODIAG and the
offsets have no documented range). ArduPilot's INS_ACCSCAL range (0.8..1.2) is tested in
tests/test_firmware_export.py.
"""

from __future__ import annotations

import numpy as np
import pytest

from station.capture import Capture, read_capture, write_capture
from tests.test_firmware_export import XYZ, _board_corrected_capture, _saved, corrected_compass_capture, run

PX4_SCALE_MIN, PX4_SCALE_MAX = 0.1, 3.0  # module.yaml, above


def _export(capsys, tmp_path, path, fmt):
    res, db = _saved(capsys, tmp_path, path)
    out_file = tmp_path / f"out.{fmt}"
    code, out, err = run(capsys, "export", res["calibration_id"], "--format", fmt, "--db", db, "-o", out_file)
    return code, out, err, out_file


def _accel_with_scale_in_use(tmp_path, x_scale_in_use: float):
    """A board-corrected P1 capture whose CAL_ACC0_XSCALE in use is ``x_scale_in_use`` (the data
    unchanged): the export composes SCALE = SCALE_in_use * SCALE_fit, SCALE_fit near 1."""
    path, _o, _s, _o_old, s_old = _board_corrected_capture(tmp_path, "px4", 4)
    cap = read_capture(path)
    meta = dict(cap.meta, **{"param.CAL_ACC0_XSCALE": repr(x_scale_in_use)})
    out = tmp_path / "scaled.csv"
    write_capture(out, Capture(meta=meta, columns=cap.columns))
    return out, s_old


@pytest.mark.parametrize("fmt", ["px4", "qgc"])
@pytest.mark.parametrize("factor", [PX4_SCALE_MAX * 1.1, PX4_SCALE_MIN * 0.9])
def test_a_composed_accel_scale_outside_px4s_range_is_refused(capsys, tmp_path, fmt, factor):
    path, _ = _accel_with_scale_in_use(tmp_path, factor)
    code, out, err, out_file = _export(capsys, tmp_path, path, fmt)
    assert code == 2 and out == "" and err.count("\n") == 1, (code, out, err)
    assert "CAL_ACC0_XSCALE" in err and f"{PX4_SCALE_MIN:g}..{PX4_SCALE_MAX:g}" in err, err
    assert not out_file.exists()


@pytest.mark.parametrize("factor", [PX4_SCALE_MAX * 0.9, PX4_SCALE_MIN * 1.2])
def test_a_composed_accel_scale_inside_px4s_range_is_written(capsys, tmp_path, factor):
    path, _ = _accel_with_scale_in_use(tmp_path, factor)
    code, out, err, out_file = _export(capsys, tmp_path, path, "px4")
    assert code == 0, err
    x = next(float(line.split()[-1]) for line in out_file.read_text().splitlines() if "CAL_ACC0_XSCALE" in line)
    assert PX4_SCALE_MIN <= x <= PX4_SCALE_MAX and abs(x / factor - 1) < 0.1


@pytest.mark.parametrize("x_scale", [PX4_SCALE_MAX * 1.1, PX4_SCALE_MIN * 0.9])
def test_a_composed_magnetometer_scale_outside_px4s_range_is_refused(capsys, tmp_path, x_scale):
    """A board-corrected compass capture whose CAL_MAG0_XSCALE in use is out of range: the
    composed SCALE (symmetric part of fit matrix x matrix in use) follows it."""
    from solvers.simulate import simulate

    sim = simulate("compass", seed=5)
    d_G = np.column_stack([sim.columns[k] for k in ("mx", "my", "mz")]) / 100.0  # uT -> gauss
    in_use = {
        "mag_device_id": "396809",
        **{"param.CAL_MAG0_ID": "396809", "param.CAL_MAG0_PRIO": "75", "param.CAL_MAG0_ROT": "0"},
        **{"param.SENS_BOARD_ROT": "0"},
        **{f"param.CAL_MAG0_{a}OFF": "0" for a in XYZ},
        **{f"param.CAL_MAG0_{a}SCALE": repr(x_scale if a == "X" else 1.0) for a in XYZ},
        **{f"param.CAL_MAG0_{a}ODIAG": "0" for a in XYZ},
    }
    path = corrected_compass_capture(tmp_path / "mag.csv", sim, d_G, "px4", in_use)
    code, out, err, out_file = _export(capsys, tmp_path, path, "px4")
    assert code == 2 and out == "" and err.count("\n") == 1, (code, out, err)
    assert "CAL_MAG0_XSCALE" in err and f"{PX4_SCALE_MIN:g}..{PX4_SCALE_MAX:g}" in err, err
    assert not out_file.exists()
