"""P2 centrifuge calibration: exact fit and the paper's method on simulated data and on the
paper's own Table 1 (as printed, with its lost minus signs found and named)."""

from __future__ import annotations

import json

import numpy as np

from solvers import centrifuge as C
from solvers.simulate import simulate
from station.capture import Capture, read_capture, write_capture
from station.cli import main

TRUTH = {"S": [1.29, 1.21, 1.26], "b": [0.213, 0.256, 0.516], "D": [0.57e-4, 0.31e-4, 0.45e-4]}
# Table 1 rows (1-based) that do not fit the model as printed; each agrees with one sign flipped.
BAD_ROWS = [1, 5, 6, 9, 10, 13, 15, 16, 17, 19, 20, 21, 25, 29, 30, 33, 37, 41, 45, 49, 50, 53, 57]


def rows(sim):
    N = np.column_stack([sim.columns[c] for c in ("ax", "ay", "az")])
    return N, C.norm_target(sim.columns["speed_rad_s"], 1.0, 9.8)


def test_paper_and_exact_agree_on_noise_free_data():
    """No noise: the exact fit returns the truth to rounding (1e-9 g outputs); the paper's
    method to its series truncation (O(D³x⁵): ~1e-7 in S and b, ~0.1 % of D)."""
    sim = simulate("accel-centrifuge", seed=3, noise_g=0.0)
    N, rho = rows(sim)
    e, p = C.exact_fit(N, rho), C.paper_fit(N, rho)
    for k, tol_e, tol_p in (("S", 1e-9, 1e-6), ("b", 1e-8, 2e-6), ("D", 1e-11, 2e-7)):
        t = np.array(sim.truth[k])
        assert np.all(np.abs(e.params[k] - t) < tol_e), k
        assert np.all(np.abs(p.params[k] - t) < tol_p), k
        assert np.all(np.abs(p.params[k] - e.params[k]) < tol_p), k


def test_exact_fit_coverage_over_seeds():
    """Noise 1e-5 g, noise level unknown to the fit (estimated from residuals): ~68 % within
    1σ and ~95 % within 2σ over 150 seeds × 9 parameters (±4 binomial σ for 150 seeds)."""
    z = []
    for seed in range(150):
        sim = simulate("accel-centrifuge", seed=1000 + seed)
        N, rho = rows(sim)
        r = C.exact_fit(N, rho)
        z.append(np.concatenate([(r.params[k] - np.array(sim.truth[k])) / r.sigma[k] for k in "SbD"]))
    z = np.array(z)
    assert abs(np.mean(np.abs(z) < 1) - 0.683) < 0.15
    assert abs(np.mean(np.abs(z) < 2) - 0.954) < 0.07


def test_known_noise_gives_right_weights():
    """With the output noise given, the reduced χ² is ~1 and σ follows the noise."""
    sim = simulate("accel-centrifuge", seed=5, noise_g=1e-5)
    N, rho = rows(sim)
    r = C.exact_fit(N, rho, sigma_N=1e-5)
    assert 0.5 < r.fit.reduced_chi2 < 1.6  # 51 dof: 1 ± 0.2 (1σ)
    assert not r.fit.misfit_scaled


def test_paper_closed_forms_invert_the_coefficients():
    """Coefficients made from known S, b, D by the module's own formulas come back exactly,
    both for the paper's printed coefficients and the consistent third-order ones."""
    S, b, D = np.array(TRUTH["S"]), np.array(TRUTH["b"]), np.array(TRUTH["D"])
    s, K = 1 / S, D * b / S
    for variant, (f1, f2, f3) in (
        ("paper", ((1 + K) * (1 + 2 * K), 1 + 6 * K + 6 * K * K, 1 + 2 * K)),
        ("third-order", (1 + 3 * K + 10 * K * K, 1 + 6 * K + 30 * K * K, 1 + 10 * K)),
    ):
        q = np.concatenate([[0.0], -2 * b * s * s * f1, s * s * f2, -2 * D * s**3 * f3, 5 * D * D * s**4])
        p = C.paper_closed_form(q, variant)
        assert np.allclose(p["S"], S, rtol=1e-12) and np.allclose(p["b"], b, rtol=1e-10)
        assert np.allclose(p["D"], D, rtol=1e-10)


def test_table1_rows_that_disagree_are_found(shared_data):
    cap = read_capture(shared_data / "wang2021_centrifuge" / "table1.capture.csv")
    N = np.column_stack([cap.columns[c] for c in ("ax", "ay", "az")])
    rho = C.norm_target(cap.columns["speed_rad_s"], 1.0, 9.8)
    scr = C.screen_rows(N, rho)
    assert (np.flatnonzero(~scr.used) + 1).tolist() == BAD_ROWS
    assert all("lost minus sign" in scr.hints[k - 1] for k in BAD_ROWS)


def test_table1_known_answer_via_cli(shared_data, capsys):
    """The 37 consistent rows give the paper's stated truth: exact to ~1e-7 (the table is
    rounded to 1e-6 g), the paper's method to ~1e-6 in S and b (its truncation)."""
    path = str(shared_data / "wang2021_centrifuge" / "table1.capture.csv")
    assert main(["calibrate", path, "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["rows_used"] == 37 and [r["row"] for r in res["rejected_rows"]] == BAD_ROWS
    for k, tol in (("S", 1e-6), ("b", 1e-6), ("D", 1e-8)):
        assert np.allclose(res["params"][k], TRUTH[k], atol=tol, rtol=0), k
    assert main(["calibrate", path, "--json", "--method", "paper"]) == 0
    res = json.loads(capsys.readouterr().out)
    for k, tol in (("S", 3e-6), ("b", 3e-6), ("D", 1e-6)):
        assert np.allclose(res["params"][k], TRUTH[k], atol=tol, rtol=0), k
    # as printed, all rows: far off, and the command says so through its residual
    assert main(["calibrate", path, "--json", "--method", "exact-all"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["rows_used"] == 60 and res["residual_rms"] > 0.01


def test_cli_refuses_without_radius_or_rows(tmp_path, capsys):
    sim = simulate("accel-centrifuge", seed=1)
    meta = {k: v for k, v in sim.meta.items() if k != "radius_m"}
    path = tmp_path / "noradius.csv"
    write_capture(path, Capture(meta, dict(sim.columns)))
    assert main(["calibrate", str(path)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "radius_m" in err
    few = {k: v[:6] for k, v in sim.columns.items()}
    path = tmp_path / "few.csv"
    write_capture(path, Capture(dict(sim.meta), few))
    assert main(["calibrate", str(path)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "6 rows" in err
    assert main(["calibrate", str(path), "--method", "nonsense"]) == 2
    assert "unknown method" in capsys.readouterr().err


def test_exact_gamma_recovers_installation_angles():
    """1e-3 rad of misalignment: the plain fit is left with residuals ~1000× the noise; the
    exact-gamma fit identifies all 6 angles (through the quadratic term, which acts on the
    sensor's axes) and recovers them within 4σ, with residuals at the noise (~1e-5 g)."""
    sim = simulate("accel-centrifuge", seed=21, effects={"misalignment": 1e-3})
    N, rho = rows(sim)
    plain = C.exact_fit(N, rho)
    r = C.exact_fit(N, rho, gamma=True)
    assert plain.residual_rms > 1e-3
    assert r.extra["gamma_gauge"] == "all" and r.residual_rms < 2e-5
    assert np.all(np.abs(r.params["gamma"] - np.array(sim.truth["gamma"])) < 4 * r.sigma["gamma"])
    assert np.all(r.sigma["gamma"] < 2e-4)
