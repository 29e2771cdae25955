"""The gyro noise (Allan) report (station.procedures.noise): known answers on simulated
white rate noise, the time a P4 run needs, and refusals."""

from __future__ import annotations

import math

import numpy as np
import pytest

from station.procedures.noise import DEG_H_RAD_S, format_duration, noise_report

FS_HZ = 100.0
ARW_DEG_RT_H = 0.5  # white rate noise, 0.5 °/√h
N_RAD_RT_S = math.radians(ARW_DEG_RT_H) / 60.0


def white(n, seed=0, bias_deg_h=(10.0, -20.0, 5.0)):
    rng = np.random.default_rng(seed)
    return rng.normal(scale=N_RAD_RT_S * math.sqrt(FS_HZ), size=(n, 3)) + np.asarray(bias_deg_h) * DEG_H_RAD_S


def test_angle_random_walk_and_the_white_slope():
    """ARW = sqrt(c0) of the fitted model: 0.5 °/√h back within 5 % (c0 rests on the short
    τ, estimated from ~10⁵ terms: ~1 % scatter); ADEV(τ) = N/√τ at τ = 1 s within 5 %."""
    r = noise_report(white(120_000), FS_HZ, "rad/s")
    np.testing.assert_allclose(r.arw_deg_rt_h, ARW_DEG_RT_H, rtol=0.05)
    i = int(np.argmin(np.abs(r.taus_s - 1.0)))
    np.testing.assert_allclose(r.adev_deg_h[i] * DEG_H_RAD_S, N_RAD_RT_S / math.sqrt(r.taus_s[i]), rtol=0.05)
    assert np.all(np.abs(r.mean_deg_h - [10.0, -20.0, 5.0]) <= 4 * r.sigma_mean_deg_h)
    # white noise has no floor: the minimum ADEV sits at the longest τ (or near it)
    assert np.all(r.bias_instability_tau_s >= r.taus_s[-1] / 3)
    assert r.duration_s == pytest.approx(1200.0)


def test_time_needed_for_an_accuracy():
    """White noise: T = (ARW / accuracy)² (in hours); the noise model may add a floor fitted
    from the longest τ, so the answer is at least that and grows as the accuracy tightens."""
    r = noise_report(white(120_000, seed=1), FS_HZ, "rad/s")
    t_white = (ARW_DEG_RT_H / 2.0) ** 2 * 3600.0  # 225 s for 2 °/h
    need = r.time_needed_s(2.0)
    assert np.all(need >= 0.8 * t_white) and np.all(need < 4 * t_white), need
    assert np.all(r.time_needed_s(1.0) > 3 * need)
    js = r.to_json(2.0)
    assert js["accuracy_deg_h"] == 2.0 and len(js["time_needed_s"]) == 3 and len(js["adev_deg_h"]) == 3


def test_deg_per_s_gives_the_same_report():
    y = white(20_000, seed=2)
    a = noise_report(y, FS_HZ, "rad/s")
    b = noise_report(np.degrees(y), FS_HZ, "deg/s")
    np.testing.assert_allclose(b.arw_deg_rt_h, a.arw_deg_rt_h, rtol=1e-9)
    np.testing.assert_allclose(b.adev_deg_h, a.adev_deg_h, rtol=1e-9)


def test_refusals():
    with pytest.raises(ValueError, match="counts"):
        noise_report(white(1000), FS_HZ, "counts")
    with pytest.raises(ValueError, match="only 10 samples"):
        noise_report(white(10), FS_HZ, "rad/s")
    r = noise_report(white(1000), FS_HZ, "rad/s")
    for bad in (0.0, -1.0, float("nan"), "1"):
        with pytest.raises(ValueError, match="positive number"):
            r.time_needed_s(bad)


def test_format_duration():
    assert [format_duration(x) for x in (45, 600, 7300, math.inf)] == ["45 s", "10 min", "2.0 h", "never"]
    # issue 15: "needs 13,803 h" where the README promises "never": beyond a day is never
    assert format_duration(13803 * 3600.0) == "never" and format_duration(23.5 * 3600) == "23.5 h"


def test_p4_record_verdict_names_the_axes_that_never_get_there():
    """The noise run's line under its table: one axis that never reaches the accuracy made
    it say "No still P4 record reaches 1σ ≤ 1 °/h" beside x needing 2.6 h and y 84 min."""
    from station.procedures.noise import p4_record_verdict

    assert p4_record_verdict([9360.0, 5040.0, 600.0], 1.0) == "For 1σ ≤ 1 °/h a still P4 record needs 2.6 h."
    line = p4_record_verdict([9360.0, 5040.0, math.inf], 1.0)
    assert line.startswith("No still P4 record reaches 1σ ≤ 1 °/h on every axis: the fitted noise floor of z ")
    assert line.endswith("is above it; x alone needs 2.6 h, y alone needs 84 min.")
    line = p4_record_verdict([math.inf, 30 * 3600.0, 60.0], 0.5)  # y: finite but past a day
    assert "noise floor of x and y " in line and "or within a hair of it (> 24 h)" in line
    assert line.endswith("; z alone needs 60 s.")
    assert p4_record_verdict([math.inf] * 3, 1.0).endswith(
        "of x and y and z (bias instability, rate random walk) is above it."
    )
