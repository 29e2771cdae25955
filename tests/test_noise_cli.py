"""`station noise`: Allan figures of a still record recover the simulated noise density and random
walk within their stated 1-sigma, and imu.yaml is in Kalibr's units.

The records follow Kalibr's own discrete-time IMU noise model (ethz-asl/kalibr wiki, "IMU Noise
Model"): white noise n_d[k] = sigma / sqrt(dt) * w[k], and a bias random walk
b_d[k] = b_d[k-1] + sigma_b * sqrt(dt) * w[k], w ~ N(0, 1), per axis.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from station.capture import Capture, read_capture, write_capture
from tests.station_run import assert_one_line_refusal, run_station
from tests.station_run import run_main as run

RATE_HZ = 200.0
GYRO_N, GYRO_K = (3e-4, 4e-4, 5e-4), (2e-5, 4e-5, 3e-5)  # rad/s/√Hz, rad/s²/√Hz
ACCEL_N, ACCEL_K = (2e-3, 1.5e-3, 2.5e-3), (1e-4, 2e-4, 3e-4)  # m/s²/√Hz, m/s³/√Hz


def kalibr_noise(rng, n, density, random_walk, dt=1.0 / RATE_HZ):
    d, k = np.asarray(density), np.asarray(random_walk)
    return d / np.sqrt(dt) * rng.normal(size=(n, 3)) + np.cumsum(k * np.sqrt(dt) * rng.normal(size=(n, 3)), axis=0)


def still_capture(path, seed, seconds=600.0):
    rng = np.random.default_rng(seed)
    n = int(seconds * RATE_HZ)
    g = kalibr_noise(rng, n, GYRO_N, GYRO_K) + [0.001, -0.002, 0.0005]
    a = kalibr_noise(rng, n, ACCEL_N, ACCEL_K) + [0.1, -0.05, 9.81]
    cols = {
        "t": np.arange(n) / RATE_HZ,
        "ax": a[:, 0],
        "ay": a[:, 1],
        "az": a[:, 2],
        "gx": g[:, 0],
        "gy": g[:, 1],
        "gz": g[:, 2],
    }
    meta = {
        "procedure": "gyro-drift",
        "device": "NOISE-1",
        "accel_unit": "m/s^2",
        "gyro_unit": "rad/s",
        "sample_rate_hz": str(RATE_HZ),
    }
    write_capture(path, Capture(meta=meta, columns=cols, path=path))
    return path


def test_recovers_density_and_random_walk_within_stated_sigma_and_writes_kalibr_yaml(capsys, tmp_path):
    cap = still_capture(tmp_path / "still.csv", seed=11)
    yaml_path = tmp_path / "imu.yaml"
    code, out, err = run(capsys, "noise", cap, "--format", "kalibr", "--out", yaml_path, "--json")
    assert code == 0, err
    doc = json.loads(out)
    for kind, N, K in (("gyro", GYRO_N, GYRO_K), ("accel", ACCEL_N, ACCEL_K)):
        s = doc["sensors"][kind]
        z_n = (np.array(s["noise_density"]) - N) / np.array(s["noise_density_sigma"])
        z_k = (np.array(s["random_walk"]) - K) / np.array(s["random_walk_sigma"])
        # both sigmas are honest (rms z ≈ 1 in benchmarks/bench_noise.py): 3 sigma per axis here
        assert np.all(np.abs(z_n) < 3) and np.all(np.abs(z_k) < 3), (kind, z_n, z_k)
        # the 68 % interval of each ADEV point brackets it
        adev, lo, hi = (np.array(s[k]) for k in ("adev", "adev_lo_68", "adev_hi_68"))
        assert np.all(lo < adev) and np.all(adev < hi)
    values = {}
    for line in yaml_path.read_text().splitlines():
        if line and not line.startswith("#"):
            key, _, rest = line.partition(":")
            values[key] = rest.split("#")[0].strip()
    assert set(values) == {
        "accelerometer_noise_density",
        "accelerometer_random_walk",
        "gyroscope_noise_density",
        "gyroscope_random_walk",
        "update_rate",
        "rostopic",
    }
    assert float(values["update_rate"]) == RATE_HZ and values["rostopic"] == "/imu0"
    # one value per sensor: the largest axis, in Kalibr's units (SI: rad/s/√Hz, m/s²/√Hz, ...)
    assert float(values["gyroscope_noise_density"]) == pytest.approx(
        max(doc["sensors"]["gyro"]["noise_density"]), rel=1e-5
    )
    assert float(values["accelerometer_random_walk"]) == pytest.approx(
        max(doc["sensors"]["accel"]["random_walk"]), rel=1e-5
    )


def test_text_with_plot_and_bad_input(capsys, tmp_path, monkeypatch):
    monkeypatch.delenv("NO_COLOR", raising=False)
    cap = still_capture(tmp_path / "still.csv", seed=3, seconds=120.0)
    code, out, err = run(capsys, "noise", cap)
    assert code == 0 and "rad/s/√Hz" in out and "m/s³/√Hz" in out and "Allan deviation" in out
    assert "\x1b[" not in out  # not a terminal: no colour
    # 120 s is too short for K (crossover ~26-40 s): an axis fitted 0, or K's sigma not to be trusted
    assert re.search(r"random walk (poorly|not) resolved", out), out
    table = tmp_path / "table.csv"
    write_capture(
        table,
        Capture(
            meta={"procedure": "accel-tabletop", "device": "X", "accel_unit": "g"},
            columns={
                "position": np.array(["a", "b"], dtype=object),
                "ax": np.zeros(2),
                "ay": np.zeros(2),
                "az": np.ones(2),
            },
            path=table,
        ),
    )
    code, out, err = run(capsys, "noise", table)
    assert code == 2 and out == "" and err.count("\n") == 1 and "table of averages" in err
    code, out, err = run(capsys, "noise", cap, "--out", tmp_path / "x.yaml")
    assert code == 2 and "--format kalibr" in err and not (tmp_path / "x.yaml").exists()


def test_a_stated_rate_the_time_column_contradicts_is_refused(capsys, tmp_path):
    """A record stating 2 Hz on 200 Hz rows gave a noise density 10x too high (the Allan
    analysis took the stated rate over the t column) with exit 0. Now one line naming the
    metadata's line and both rates, nothing written; a record with a gap (an unplug) or
    bursty time stamps still gives its figures, at the stated rate."""
    cap = still_capture(tmp_path / "still.csv", seed=4, seconds=120.0)
    text = cap.read_text()
    lines = text.splitlines()
    lineno = next(i for i, line in enumerate(lines, 1) if line.startswith("# sample_rate_hz"))
    bad = tmp_path / "bad.csv"
    bad.write_text(text.replace("# sample_rate_hz: 200.0", "# sample_rate_hz: 2"))
    code, out, err = run(capsys, "noise", bad, "--format", "kalibr", "--out", tmp_path / "imu.yaml")
    assert code == 2 and out == "" and err.count("\n") == 1, err
    assert f"bad.csv:{lineno}: metadata 'sample_rate_hz': 2 Hz, but the t column holds 200 rows per second" in err
    assert not (tmp_path / "imu.yaml").exists()
    good = json.loads(run(capsys, "noise", cap, "--json")[1])
    # an unplug: a third of the rows gone from the middle (rows per second fall, the median step does not)
    c = read_capture(cap)
    n = len(c.columns["t"])
    keep = np.r_[0 : n // 3, 2 * n // 3 : n]
    gap = tmp_path / "gap.csv"
    write_capture(gap, Capture(meta=dict(c.meta), columns={k: v[keep] for k, v in c.columns.items()}, path=gap))
    code, out, err = run(capsys, "noise", gap, "--json")
    assert code == 0, err
    assert json.loads(out)["sample_rate_hz"] == good["sample_rate_hz"] == RATE_HZ
    # bursty host stamps: rows arrive in fives with one time each (the median step is 0)
    bursty = tmp_path / "bursty.csv"
    t = np.repeat(c.columns["t"][::5], 5)[:n]
    write_capture(bursty, Capture(meta=dict(c.meta), columns=dict(c.columns, t=t), path=bursty))
    code, out, err = run(capsys, "noise", bursty, "--json")
    assert code == 0, err


@pytest.mark.parametrize("name", ["sample_log_small.ulg", "flight.csv"])
def test_noise_of_a_binary_log_says_what_it_is_and_how_to_read_it(tmp_path, shared_data, name):
    """`station noise flight.ulg` said 'NUL byte at column 13: binary data, not a text
    capture'; the file is a PX4 ULog, whatever its name, and station import reads it."""
    log = tmp_path / name
    log.write_bytes((shared_data / "px4_ulog" / "original" / "sample_log_small.ulg").read_bytes())
    res = run_station("noise", log, "--no-plot")
    assert_one_line_refusal(res, f"{log}: a PX4 ULog file, not a capture", "station import")


@pytest.mark.parametrize("no_color", ["", "1"])
def test_the_plot_on_a_real_terminal_is_coloured_not_escaped_text(tmp_path, no_color):
    """On a terminal `station noise` printed its coloured plot through the stream that escapes
    terminal-active characters: 32 rows of '\\x1b[48;5;15m' text around the dots, wrapped
    across an 80-column screen. The plot is the station's own text (drift's plot already went
    out as such): colour codes reach the terminal as colour, or none with NO_COLOR."""
    import os

    from tests.test_terminal_safety import _pty_run

    cap = still_capture(tmp_path / "still.csv", seed=5, seconds=120.0)
    env = {k: v for k, v in os.environ.items() if k != "NO_COLOR"}
    env.update({"NO_COLOR": no_color, "COLUMNS": "80", "LINES": "24"})
    rc, out = _pty_run("noise", cap, env=env)
    text = out.decode("utf-8")
    assert rc == 0 and "Allan deviation" in text, text[-400:]
    assert "\\x1b" not in text
    assert ("\x1b[" in text) == (not no_color)
    plot = [re.sub(r"\x1b\[[0-9;]*m", "", line) for line in text.splitlines() if "┤" in line]
    assert plot and max(len(line) for line in plot) <= 80  # as the screen shows it


@pytest.mark.parametrize("topic", ["/imu0\nupdate_rate: 1", "a: b", "/imu0 # x", ""])
def test_a_rostopic_that_is_no_ros_name_is_refused_not_written_into_imu_yaml(tmp_path, topic):
    """`--rostopic` went unquoted into imu.yaml: a newline added a second `update_rate` (the
    one a YAML loader keeps is the last, 1 Hz), ': ' made a file no YAML loader reads. A ROS
    name has letters, digits, _ and / only (wiki.ros.org/Names); anything else is one line,
    exit 2, no imu.yaml."""
    cap = still_capture(tmp_path / "still.csv", seed=6, seconds=60.0)
    out = tmp_path / "imu.yaml"
    res = run_station(
        "noise", cap, "--no-plot", "--format", "kalibr", "--out", out, "--rostopic", topic, subprocess_run=True
    )
    assert res.returncode == 2 and res.stdout == "", (res.returncode, res.stdout, res.stderr)
    assert res.stderr.count("\n") == 1 and "--rostopic" in res.stderr and "ROS topic name" in res.stderr
    assert "Traceback" not in res.stderr and not out.exists()
    res = run_station("noise", cap, "--no-plot", "--format", "kalibr", "--out", out, "--rostopic", "/cam0/imu_raw")
    assert res.returncode == 0, res.stderr
    keys = [line.split(":")[0] for line in out.read_text().splitlines() if line and not line.startswith("#")]
    assert sorted(keys) == sorted(set(keys)) and "rostopic: /cam0/imu_raw" in out.read_text().splitlines()
