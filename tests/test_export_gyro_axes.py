"""Firmware export of a gyro drift: offsets on the sensor's own axes, not P4's body frame.

Known answer: one simulated P4 record written twice, once in P4's body frame (x fwd, y up,
z right) and once as a sensor mounted 'x forward, y left, z up' with its x gyro reversed
(the sunsided_marg convention). Both give the same body-frame drift d; the firmware offsets
of the second must be d on the sensor's axes: (−d_x, −d_z, +d_y).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from station.capture import Capture, write_capture
from station.cli import main


def _run(capsys, *argv) -> str:
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    assert code == 0, out.err
    return out.out


def _params(text: str) -> dict[str, float]:
    out = {}
    for line in text.splitlines():
        if line.startswith("param set "):
            _, _, name, value = line.split()
        elif line and not line.startswith("#"):
            name, value = line.split(",")
        else:
            continue
        out[name] = float(value)
    return out


@pytest.fixture(scope="module")
def captures(tmp_path_factory):
    from solvers.simulate import simulate

    sim = simulate("gyro-drift", seed=7)
    folder = tmp_path_factory.mktemp("gyro")
    body = folder / "body.csv"
    write_capture(body, Capture(meta=sim.meta, columns=sim.columns, path=body))
    c = sim.columns
    # sensor axes: x = body x (reading reversed for the gyro), y = left = −body z, z = up = body y
    cols = dict(c, gx=-c["gx"], gy=-c["gz"], gz=c["gy"], ax=c["ax"], ay=-c["az"], az=c["ay"])
    sensor = folder / "sensor.csv"
    write_capture(
        sensor, Capture(meta=dict(sim.meta, frame="x forward, y left, z up", gyro_flip="x"), columns=cols, path=sensor)
    )
    return body, sensor


@pytest.mark.parametrize(
    "fmt, names",
    [
        ("ardupilot", ("INS_GYROFFS_X", "INS_GYROFFS_Y", "INS_GYROFFS_Z")),  # AP_InertialSensor.cpp @Param GYROFFS_X
        ("px4", ("CAL_GYRO0_XOFF", "CAL_GYRO0_YOFF", "CAL_GYRO0_ZOFF")),
    ],
)
def test_gyro_offsets_are_on_the_sensor_axes(tmp_path, capsys, captures, fmt, names):
    body, sensor = captures
    db = tmp_path / "s.db"
    d_body = json.loads(_run(capsys, "--db", db, "calibrate", body, "--json", "--save"))
    d_sensor = json.loads(_run(capsys, "--db", db, "calibrate", sensor, "--json", "--save", "--device", "MOUNTED"))
    d = np.array(d_body["params"]["drift"])
    # the same drift in P4's frame either way (float round-off of the written columns only)
    np.testing.assert_allclose(d_sensor["params"]["drift"], d, rtol=1e-6, atol=1e-12)

    ids = ["--device-id", "1310988"] if fmt == "px4" else []
    same = _params(_run(capsys, "--db", db, "export", d_body["calibration_id"], "--format", fmt, *ids))
    np.testing.assert_allclose([same[n] for n in names], d, rtol=1e-8)  # body frame = sensor frame here

    text = _run(capsys, "--db", db, "export", d_sensor["calibration_id"], "--format", fmt, *ids)
    mounted = _params(text)
    np.testing.assert_allclose([mounted[n] for n in names], [-d[0], -d[2], d[1]], rtol=1e-6, atol=1e-12)
    assert "mapped back from P4's body frame" in text  # the file says what it converted
