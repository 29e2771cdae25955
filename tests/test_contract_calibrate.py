"""`station calibrate FILE --json` against ../shared/spec/calibrate.md, exactly.

For all five procedures, on simulated captures and on the shared real datasets that support
the procedure: the required keys, each procedure's parameter names and shapes, `uncertainty`
with the same shape as `params` (1σ, never negative), valid JSON without NaN/Infinity
literals. The real CLI (`station.cli.main`) writes the JSON; we parse what it printed.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from station.capture import Capture, write_capture
from station.cli import main

REQUIRED = {"procedure", "device", "model", "params", "uncertainty", "residual_rms", "n_positions", "warnings"}
BEAM = {"dK", "alpha_deg", "beta_deg", "gamma_deg", "sigma_mps"}
REFERENCE = {"north_nT", "east_nT", "down_nT", "total_nT", "inclination_deg", "declination_deg"}
GYRO_MODE_B = {"drift", "mode", "pitch_deg", "roll_deg", "earth_rate_body"}


def _no_constants(name):
    raise ValueError(f"JSON literal {name} is not JSON (calibrate.md: valid JSON)")


def calibrate_json(capsys, path, *extra) -> dict:
    code = main(["calibrate", str(path), "--json", *extra])
    out = capsys.readouterr()
    assert code == 0, out.err
    return json.loads(out.out, parse_constant=_no_constants)


def is_num(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def vec(x, n=3, nullable=False) -> bool:
    return isinstance(x, list) and len(x) == n and all(is_num(v) or (nullable and v is None) for v in x)


def mat(x, nullable=False) -> bool:
    return isinstance(x, list) and len(x) == 3 and all(vec(r, 3, nullable) for r in x)


def same_shape(p, s, where="") -> None:
    """σ mirrors the parameter: dict keys, list lengths; a number's σ is a number >= 0 or null."""
    if isinstance(p, dict):
        assert isinstance(s, dict) and set(s) == set(p), f"uncertainty{where}: keys {sorted(s)} vs {sorted(p)}"
        for k in p:
            same_shape(p[k], s[k], f"{where}.{k}")
    elif isinstance(p, list):
        assert isinstance(s, list) and len(s) == len(p), f"uncertainty{where}: length"
        for i, (a, b) in enumerate(zip(p, s)):
            same_shape(a, b, f"{where}[{i}]")
    elif p is None:
        assert s is None, f"uncertainty{where}: σ of a missing value"
    else:
        assert is_num(p), f"params{where} = {p!r}"
        assert s is None or (is_num(s) and s >= 0), f"uncertainty{where} = {s!r}"


def check_common(d: dict, procedure: str) -> None:
    assert REQUIRED <= set(d), f"missing {REQUIRED - set(d)}"
    assert d["procedure"] == procedure
    assert isinstance(d["device"], str) and d["device"]
    assert isinstance(d["model"], str) and d["model"]
    assert is_num(d["residual_rms"]) and d["residual_rms"] >= 0
    assert isinstance(d["n_positions"], int) and not isinstance(d["n_positions"], bool) and d["n_positions"] >= 1
    assert isinstance(d["warnings"], list) and all(isinstance(w, str) and w for w in d["warnings"])
    params, unc = d["params"], d["uncertainty"]
    assert isinstance(params, dict) and isinstance(unc, dict)
    # same shape; a string (gyro-drift's mode) has no σ and may be absent from uncertainty
    strings = {k for k, v in params.items() if isinstance(v, str)}
    assert set(unc) <= set(params) and set(params) - set(unc) <= strings
    for k in set(params) - strings:
        same_shape(params[k], unc[k], f".{k}")


def check_tabletop(d: dict) -> None:
    assert set(d["params"]) == {"B", "M"}
    assert vec(d["params"]["B"]) and mat(d["params"]["M"])
    assert isinstance(d.get("gauge"), str) and d["gauge"]  # which gauge fixes the rotation the norm cannot see
    if d["gauge"] == "upper-triangular":
        M = d["params"]["M"]
        assert M[1][0] == M[2][0] == M[2][1] == 0.0
    assert all(d["params"]["M"][i][i] > 0 for i in range(3))  # diag(M) = scale factors S


def check_centrifuge(d: dict) -> None:
    p = d["params"]
    assert set(p) in ({"S", "b", "D"}, {"S", "b", "D", "gamma"})
    assert vec(p["S"]) and vec(p["b"]) and vec(p["D"])
    if "gamma" in p:  # γxy, γxz, γyx, γyz, γzx, γzy
        assert vec(p["gamma"], 6, nullable=True)


def check_compass(d: dict) -> None:
    p = d["params"]
    assert set(p) == {"hard_iron", "soft_iron", "reference"}
    assert vec(p["hard_iron"]) and mat(p["soft_iron"])
    W = p["soft_iron"]
    assert W[1][0] == W[2][0] == W[2][1] == 0.0  # upper triangular
    ref = p["reference"]
    assert isinstance(ref, dict) and set(ref) == REFERENCE
    anchored = all(is_num(v) for v in ref.values())
    assert anchored or all(v is None for v in ref.values())  # no place: no IGRF, all null, and a warning says so
    if not anchored:
        assert any("IGRF" in w for w in d["warnings"])
    else:
        r = ref
        assert math.isclose(math.hypot(r["north_nT"], r["east_nT"], r["down_nT"]), r["total_nT"], rel_tol=1e-9)


def check_gyro(d: dict) -> None:
    p = d["params"]
    assert vec(p["drift"])
    assert p["mode"] in ("static", "reference")
    if p["mode"] == "static":  # mode B
        assert set(p) == GYRO_MODE_B
        assert is_num(p["pitch_deg"]) and is_num(p["roll_deg"])
        # earth_rate_body [3] rad/s; without latitude_deg it cannot be known: null, and a warning says so
        assert vec(p["earth_rate_body"]) or (
            p["earth_rate_body"] is None and any("latitude" in w for w in d["warnings"])
        )
        if p["earth_rate_body"] is not None:
            assert math.hypot(*p["earth_rate_body"]) <= 7.2922e-5 * (1 + 1e-6)  # no more than Earth's rate
    else:
        assert set(p) == {"drift", "mode"}


def check_ldv(d: dict) -> None:
    p = d["params"]
    assert set(p) == {"beam1", "beam2", "beam3", "condition_number"}
    assert is_num(p["condition_number"]) and p["condition_number"] >= 1
    for b in ("beam1", "beam2", "beam3"):
        assert isinstance(p[b], dict) and set(p[b]) == BEAM
        assert all(is_num(v) for v in p[b].values())
        assert all(0 <= p[b][a] <= 180 for a in ("alpha_deg", "beta_deg", "gamma_deg"))
        cosines = sum(math.cos(math.radians(p[b][a])) ** 2 for a in ("alpha_deg", "beta_deg", "gamma_deg"))
        assert math.isclose(cosines, 1.0, abs_tol=1e-6)  # direction angles of one unit vector


CHECKS = {
    "accel-tabletop": check_tabletop,
    "accel-centrifuge": check_centrifuge,
    "compass": check_compass,
    "gyro-drift": check_gyro,
    "ldv": check_ldv,
}

# small but realistic simulations (kept short for the suite's time budget)
SIMULATED = [
    ("accel-tabletop", {"hold_s": 5.0}, None),
    ("accel-tabletop", {"hold_s": 5.0, "label_positions": False}, None),  # upper-triangular gauge
    ("accel-tabletop", {"averages": True}, None),
    ("accel-centrifuge", {}, None),
    ("accel-centrifuge", {}, "exact-gamma"),
    ("compass", {}, None),
    ("gyro-drift", {}, None),
    ("gyro-drift", {"mode": "reference", "duration_s": 60.0}, None),
    ("ldv", {"duration_s": 300.0}, None),
    ("ldv", {"duration_s": 300.0, "reference": "nav"}, None),
]


@pytest.mark.parametrize(
    "procedure, options, method",
    SIMULATED,
    ids=[
        f"{p}-{'-'.join(f'{k}={v}' for k, v in o.items()) or 'default'}{'-' + m if m else ''}" for p, o, m in SIMULATED
    ],
)
def test_simulated_capture_matches_the_contract(tmp_path, capsys, procedure, options, method):
    from solvers.simulate import simulate

    sim = simulate(procedure, seed=11, **options)
    path = tmp_path / "capture.csv"
    write_capture(path, Capture(meta=sim.meta, columns=sim.columns, path=path))
    d = calibrate_json(capsys, path, *(["--method", method] if method else []))
    check_common(d, procedure)
    CHECKS[procedure](d)
    assert d["device"] == sim.meta["device"]
    if method == "exact-gamma":
        assert "gamma" in d["params"]


REAL = [
    ("imu_tk_xsens/imu_tk_xsens.capture.csv", "accel-tabletop", None),
    ("mpu6050_unc/mpu6050_unc_calibration.capture.csv", "accel-tabletop", None),
    ("imucal_ferraris/imucal_ferraris_labelled.capture.csv", "accel-tabletop", "six-position"),
    ("wang2021_centrifuge/table1.capture.csv", "accel-centrifuge", None),
    ("sunsided_marg/sunsided_full_sphere.capture.csv", "compass", None),
    ("sunsided_marg/sunsided_unmoved_x_forward.capture.csv", "gyro-drift", None),
]


@pytest.mark.parametrize("rel, procedure, method", REAL, ids=[Path(r).name for r, _, _ in REAL])
def test_real_capture_matches_the_contract(shared_data, capsys, rel, procedure, method):
    path = shared_data / rel
    if not path.exists():
        pytest.skip(f"{rel} is not in ../shared/data")
    d = calibrate_json(capsys, path, *(["--method", method] if method else []))
    check_common(d, procedure)
    CHECKS[procedure](d)


def test_device_option_overrides_the_device(tmp_path, capsys):
    from solvers.simulate import simulate

    sim = simulate("accel-centrifuge", seed=2)
    path = tmp_path / "c.csv"
    write_capture(path, Capture(meta=sim.meta, columns=sim.columns, path=path))
    d = calibrate_json(capsys, path, "--device", "IMU-0042")
    assert d["device"] == "IMU-0042"
