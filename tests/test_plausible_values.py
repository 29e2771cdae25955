"""Magnitudes no sensor of the kind can report, refused where the data are read, naming the
file, the line and the column: `inspect` and `import` accepted a cell of 1e308 (only
`calibrate`, `diagnose` and `noise` screened it, after reading), and a log sample far beyond
any accelerometer became a capture.

The bounds (station.capture.PLAUSIBLE_SI, for columns in a physical unit) are large multiples of the widest full-scale range
of any part of the kind, so that no real record meets them: the bound must let through what
such parts report (the figures below, from their datasheets) and refuse what is beyond it.
"""

from __future__ import annotations

import numpy as np
import pytest

from station.capture import Capture, read_capture, write_capture
from tests.station_run import assert_one_line_refusal, run_station

# Widest full-scale ranges of real parts (datasheets): Endevco 7270A-200K piezoresistive shock
# accelerometer ±200 000 g; Analog Devices ADXRS649 gyro ±20 000 °/s; TI TMAG5170A2 3-D Hall
# sensor ±300 mT. A record of any of them at full scale must read.
WIDEST_ACCEL_G = 200_000.0
WIDEST_GYRO_DEG_S = 20_000.0
WIDEST_MAG_GAUSS = 3_000.0  # 300 mT


def _capture(path, units: dict[str, str], cells: dict[str, float], n: int = 300):
    """A still gyro-drift time series (accel, gyro, mag) in ``units``, one cell per column of
    ``cells`` set at row 150 (file line = header line + 151)."""
    rng = np.random.default_rng(7)
    cols = {"t": np.arange(n) * 0.01}
    for c, v in (("ax", 0.0), ("ay", 0.0), ("az", 1.0), ("gx", 0.0), ("gy", 0.0), ("gz", 0.0)):
        cols[c] = v + rng.normal(0, 1e-3, n)
    for c, v in (("mx", 0.2), ("my", 0.0), ("mz", 0.4)):
        cols[c] = v + rng.normal(0, 1e-3, n)
    for c, v in cells.items():
        cols[c][150] = v
    meta = {"procedure": "gyro-drift", "sample_rate_hz": "100", "gyro_mode": "static", **units}
    write_capture(path, Capture(meta, cols))
    header = next(i for i, line in enumerate(path.read_text().splitlines(), 1) if line.startswith("t,"))
    return header + 151


UNITS = {"accel_unit": "g", "gyro_unit": "deg/s", "mag_unit": "gauss"}


@pytest.mark.parametrize(
    ("column", "value"),
    [("ax", 1e308), ("gy", -1e308), ("mz", 1e308), ("ax", 1e7), ("gz", 1e7), ("mx", 1e6)],
)
@pytest.mark.parametrize("command", ["inspect", "calibrate", "noise"])
def test_a_magnitude_beyond_any_sensor_is_refused_on_its_line(tmp_path, column, value, command):
    path = tmp_path / "c.csv"
    line = _capture(path, UNITS, {column: value})
    assert_one_line_refusal(run_station(command, path), f"{path}:{line}: column '{column}': {value:g} is beyond")


def test_the_full_scale_of_the_widest_parts_reads(tmp_path):
    """The bound is far from real data: the widest part of each kind at full scale reads, and
    the reader's fast path and its per-cell path (a record with an empty cell) agree."""
    path = tmp_path / "c.csv"
    cells = {"ax": -WIDEST_ACCEL_G, "gy": WIDEST_GYRO_DEG_S, "mz": WIDEST_MAG_GAUSS}
    _capture(path, UNITS, cells)
    c = read_capture(path)
    assert c.columns["ax"][150] == -WIDEST_ACCEL_G and c.columns["mz"][150] == WIDEST_MAG_GAUSS
    si = tmp_path / "si.csv"
    line = _capture(si, {"accel_unit": "m/s^2", "gyro_unit": "rad/s", "mag_unit": "nT"}, {})
    text = si.read_text().splitlines()
    cells_si = text[line - 1].split(",")
    cells_si[1] = repr(WIDEST_ACCEL_G * 9.80665)
    cells_si[4] = repr(float(np.radians(WIDEST_GYRO_DEG_S)))
    cells_si[9] = repr(WIDEST_MAG_GAUSS * 1e5)
    text[line - 1] = ",".join(cells_si)
    text[line] = ",".join(text[line].split(",")[:-1] + [""])  # an empty cell: the per-cell path
    si.write_text("\n".join(text) + "\n")
    assert read_capture(si).n_rows == 300
    assert read_capture(si, _force_slow=True).n_rows == 300


@pytest.mark.parametrize("slow", [False, True])
def test_raw_units_keep_the_generic_bound_of_the_numerics(tmp_path, slow):
    """Volts and counts have no physical factor: the format reads any finite number (as
    before) and the numerics refuse beyond 1e20, where squares start to overflow."""
    path = tmp_path / "c.csv"
    raw = {"accel_unit": "counts", "gyro_unit": "counts", "mag_unit": "counts"}
    line = _capture(path, raw, {"gx": 1e21})
    assert read_capture(path, _force_slow=slow).columns["gx"][150] == 1e21
    assert_one_line_refusal(
        run_station("calibrate", path), f"{path}:{line}: column 'gx': 1e+21 is beyond what any instrument"
    )


PLAIN = ("--procedure", "accel-tabletop", "--map", "t=time_s,ax=ax,ay=ay,az=az")


@pytest.mark.parametrize(("unit", "value"), [("g", "1e308"), ("m/s^2", "1e300"), ("g", "-2e7")])
def test_import_of_a_plain_csv_refuses_the_cell_by_its_line(tmp_path, unit, value):
    rows = ["time_s,ax,ay,az"] + [f"{i * 0.01:.2f},0.01,0.02,1.0" for i in range(400)]
    rows[7] = f"0.06,{value},0.02,1.0"
    src = tmp_path / "bench.csv"
    src.write_text("\n".join(rows) + "\n")
    out = tmp_path / "out.csv"
    res = run_station("import", src, *PLAIN, "--unit", f"accel={unit},t=s", "--out", out)
    assert_one_line_refusal(res, f"{src}:8: column 'ax': {float(value):g} is beyond")
    assert not out.exists()


def test_import_of_a_log_refuses_a_sample_beyond_any_accelerometer(tmp_path):
    """An ArduPilot log (pymavlink's own DataFlash encoder) whose IMU message holds 1e30 m/s²
    (a float32 the log can carry): refused naming the log and the sample's time."""
    from tests.test_import_ardupilot import DataFlashWriter

    log = tmp_path / "spike.bin"
    w = DataFlashWriter(log)
    rng = np.random.default_rng(2)
    for k in range(200):
        acc = np.array([0.1, -0.2, -9.8]) + rng.normal(0, 0.05, 3)
        if k == 120:
            acc[1] = 1e30
        w.imu(500_000 + k * 2500, 0, rng.normal(0, 0.01, 3), acc)
    w.close()
    out = tmp_path / "out.csv"
    res = run_station("import", log, "--procedure", "accel-tabletop", "--out", out)
    assert_one_line_refusal(res, f"{log}: ", "accelerometer", "1e+30", "is beyond", "t = 0.8 s")
    assert not out.exists()
