"""`station diagnose` on compass captures whose accelerometer is not in m/s² of specific force:
the dip rows (the angle between gravity and the field) must read the accelerometer as
`calibrate` does for tilt, through the capture's front end and with the sign it found.

- A capture the TUI records from the built-in simulated device (accelerometer in volts, with
  the data sheet's zero and sensitivity as `accel_offset` / `accel_scale_mps2_per_unit`): the
  dip rows took the raw volts, 1.65 V of zero on each axis included, and named
  `field_anomaly` with `mag_accel_misalignment` on a device with no effect (found by QA s27t in
  the TUI, ρ = 6.4 rad).
- An accelerometer that reports the gravity direction (calibrate detects it and flips it, with a
  warning): the dip rows kept its sign and named `field_anomaly` on a null capture.
"""

from __future__ import annotations

import json

import numpy as np

from station.capture import read_capture, write_capture
from tests.station_run import run_station


def _diagnose(path) -> dict:
    res = run_station("diagnose", path, "--json", "--no-plots")
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout)


def _tui_sweep(path, still_s: float = 20.0, seed: int = 0) -> None:
    """What the TUI's compass screen records from the simulated device: the unit held still
    for ``still_s``, then turned by hand (the device's sweep) until the guide has the sphere
    covered, written with the screen's front end (the data sheet's zero and sensitivity)."""
    from station.procedures import compass_guide as CG
    from station.procedures.accel_frontend import for_device
    from station.sources import SimSource

    now = [0.0]
    src = SimSource(seed=seed, speed=1.0, clock=lambda: now[0], procedure="compass").start()
    guide = CG.CompassGuide(
        sample_rate_hz=src.rate_hz,
        units=src.units,
        device_id=src.device_id,
        site=src.site,
        config=CG.CompassConfig(min_s=30.0),
        accel_frontend=for_device([], src.units.get("accel_unit"), src.nominal),
    )
    swept = False
    while guide.phase == "sweep" and now[0] < 120.0:
        now[0] += 0.05
        if not swept and now[0] >= still_s:
            src.place("sweep")
            swept = True
        b = src.drain()
        if b is not None:
            guide.update(b.t_s, b.accel, b.gyro, b.mag, b.temp_c)
    write_capture(str(path), guide.capture())


def test_a_tui_sweep_of_the_simulated_device_names_nothing(tmp_path):
    path = tmp_path / "tui_sweep.csv"
    _tui_sweep(path)
    meta = read_capture(path).meta
    assert meta["accel_unit"] == "V" and "accel_offset" in meta  # read through the front end
    j = _diagnose(path)
    assert j["verdict"] == [], j["effects"]


def test_a_gravity_direction_accelerometer_names_nothing_where_its_sign_is_flipped(tmp_path):
    src = tmp_path / "c.csv"
    res = run_station("simulate", "--procedure", "compass", "--seed", "11", "--out", src)
    assert res.returncode == 0, res.stderr
    c = read_capture(src)
    for k in ("ax", "ay", "az"):
        c.columns[k] = -np.asarray(c.columns[k], float)
    flipped = tmp_path / "gravity.csv"
    write_capture(str(flipped), c)
    res = run_station("calibrate", flipped, "--json")
    assert res.returncode == 0 and json.loads(res.stdout)["accel_sign"]["used"] == "gravity", res.stdout
    j = _diagnose(flipped)
    assert j["verdict"] == [], j["effects"]
    # and a real effect is still found through the flip: the sensors turned 1.7° apart
    res = run_station(
        "simulate", "--procedure", "compass", "--seed", "11", "--effect", "mag_accel_misalignment=0.03", "--out", src
    )
    assert res.returncode == 0, res.stderr
    c = read_capture(src)
    for k in ("ax", "ay", "az"):
        c.columns[k] = -np.asarray(c.columns[k], float)
    write_capture(str(flipped), c)
    assert _diagnose(flipped)["verdict"] == ["mag_accel_misalignment"]
