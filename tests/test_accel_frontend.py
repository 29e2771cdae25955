"""A raw accelerometer's front end for P3's tilt and heading (station/procedures/accel_frontend.py).

Known answer: a simulated compass capture (accelerometer in g) re-expressed in volts through
a front end we choose (zero 1.6 V, 0.1 V per m/s², plus a little cross-axis) and calibrated
with that front end in its metadata gives the same per-position pitch, roll and heading as
the capture in g; without it, a warning and no headings; one key without the other, or a
malformed value, is one line and exit 2."""

from __future__ import annotations

import numpy as np
import pytest

from station.calibrate import calibrate_capture
from station.capture import read_capture, write_capture
from station.cli import main
from station.procedures.accel_frontend import Frontend, for_device
from tests.station_run import run_station

G = 9.80665


@pytest.fixture(scope="module")
def capture_g(tmp_path_factory):
    out = tmp_path_factory.mktemp("fe") / "compass.csv"
    assert main(["simulate", "--procedure", "compass", "--seed", "3", "--out", str(out)]) == 0
    return read_capture(str(out))


def _in_volts(cap, K, zero):
    a = np.column_stack([np.asarray(cap.columns[k], float) for k in ("ax", "ay", "az")]) * G  # m/s²
    v = zero + a @ K.T
    cols = dict(cap.columns)
    cols.update({"ax": v[:, 0], "ay": v[:, 1], "az": v[:, 2]})
    meta = dict(cap.meta, accel_unit="V")
    return cap.__class__(meta=meta, columns=cols)


def test_volts_with_their_front_end_give_the_same_headings(capture_g, tmp_path):
    K = 0.1 * (np.eye(3) + np.array([[0, 0.01, 0], [0, 0, -0.02], [0.015, 0, 0]]))  # V per m/s²
    zero = np.array([1.6, 1.62, 1.58])
    cap_v = _in_volts(capture_g, K, zero)
    fe = Frontend(-np.linalg.inv(K) @ zero, np.linalg.inv(K), "bench sheet")
    cap_v.meta.update(fe.meta())
    assert Frontend.from_meta(cap_v.meta).source == "bench sheet"
    np.testing.assert_allclose(Frontend.from_meta(cap_v.meta).offset, zero, rtol=1e-12)
    path = tmp_path / "volts.csv"
    write_capture(str(path), cap_v)
    ref, got = calibrate_capture(capture_g), calibrate_capture(read_capture(str(path)))
    assert got["accel_frontend"] == "bench sheet" and len(got["headings"]) == len(ref["headings"]) > 4
    for a, b in zip(ref["headings"], got["headings"]):
        for k in ("pitch_deg", "roll_deg", "heading_magnetic_deg"):
            if np.isnan(a[k]):  # beyond 70° pitch: undefined in both
                assert np.isnan(b[k]), (k, b[k])
                continue
            assert abs((a[k] - b[k] + 180) % 360 - 180) < 1e-3, (k, a[k], b[k])
    # no front end: no tilt, and the warning names the keys
    bare = _in_volts(capture_g, K, zero)
    write_capture(str(tmp_path / "bare.csv"), bare)
    res = calibrate_capture(read_capture(str(tmp_path / "bare.csv")))
    assert "headings" not in res and any("accel_scale_mps2_per_unit" in w for w in res["warnings"])


@pytest.mark.parametrize(
    "meta, key",
    [
        ({"accel_offset": "1.6, 1.6, 1.6"}, "accel_offset"),
        ({"accel_offset": "1.6, 1.6", "accel_scale_mps2_per_unit": "10"}, "accel_offset"),
        ({"accel_offset": "1.6 1.6 1.6", "accel_scale_mps2_per_unit": "10, x"}, "accel_scale_mps2_per_unit"),
        ({"accel_offset": "1.6 1.6 1.6", "accel_scale_mps2_per_unit": "0"}, "accel_scale_mps2_per_unit"),
    ],
    ids=["offset alone", "two offsets", "not a number", "singular scale"],
)
def test_a_bad_front_end_is_one_line_and_exit_2(capture_g, tmp_path, meta, key):
    cap = _in_volts(capture_g, 0.1 * np.eye(3), np.full(3, 1.6))
    cap.meta.update(meta)
    path = tmp_path / "bad.csv"
    write_capture(str(path), cap)
    r = run_station("calibrate", str(path))
    assert r.returncode == 2 and r.stdout == "" and r.stderr.count("\n") == 1, r.stderr
    assert key in r.stderr and "bad.csv:" in r.stderr


def test_the_units_p1_calibration_comes_before_the_data_sheet():
    p1_v = {
        "procedure": "accel-tabletop",
        "id": 7,
        "time": "2026-11-20T10:00:00Z",
        "accepted": True,
        "params": {"B": [-19.0] * 3, "M": np.eye(3) * 11.0},
    }
    p1_v["extra"] = {"units": {"V": "V"}}
    rejected = dict(p1_v, id=8, accepted=False)
    counts = dict(p1_v, id=9, extra={"units": {"V": "counts"}})
    fe = for_device([p1_v, rejected, counts], "V", nominal=(1.65, 0.0855))
    assert fe.source == "P1 calibration #7 (2026-11-20)"
    np.testing.assert_allclose(fe(np.full(3, 19.0 / 11.0)), 0.0, atol=1e-12)
    nominal = for_device([counts], "V", nominal=(1.65, 0.0855))
    assert nominal.source == "nominal (data sheet)"
    np.testing.assert_allclose(nominal(np.array([1.65, 1.65, 1.65 + 0.0855 * G])), [0, 0, G], rtol=1e-12)
    assert for_device([], "counts") is None
