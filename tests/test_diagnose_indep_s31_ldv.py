"""`station diagnose` on LDV null captures of the independent generator
(benchmarks/indep_s27_dyn_generator.py, QA s31): a reference whose noise is unknown to the
station (no ``reference_sigma_mps``) and as large as the beams'. Through ``X`` it is common to
the three beams of an epoch, whose rows the station took as independent.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from solvers import ldv as L

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import indep_s27_dyn_generator as G  # noqa: E402


def test_ldv_null_with_a_noisy_reference_shared_by_the_beams_names_nothing(tmp_path, capsys):
    """A car at 2 Hz referenced in the navigation frame (INS velocity noise 9 mm/s, attitude noise
    0.018°, beams 7 mm/s): the reference's noise, vertical most of all, enters every beam
    (``X_j3`` ≈ 0.9) and correlates their residuals by ~0.5; the line in time that noise holds in
    all three beams at once was counted three times as independent evidence and `time_drift`
    named (QA s31 null s744031). The rows of an epoch are whitened by what the beams share."""
    from station.cli import main

    meta, cols, data, fmts, truth = G.generate_ldv(744031, "none", 0.0)
    assert truth["effect"] == "none"
    path = tmp_path / "capture.csv"
    G._write_capture(path, meta, cols, data, fmts)
    rc = main(["diagnose", str(path), "--json", "--no-plots"])
    res = json.loads(capsys.readouterr().out)
    assert rc == 0
    assert res["verdict"] == [], (res["verdict"], res["candidates"])


def test_shared_noise_correlation_reads_the_beams_common_noise():
    """The correlation of three beams' noise within an epoch (own noise plus a common reference
    noise through X), read from a residual that also holds a slow misfit (a drift): the first
    differences give it, the drift does not; an all-shared noise is held to a quarter of its own."""
    rng = np.random.default_rng(5)
    n = 20000
    X = np.array([[0.4, 0.0, 0.9], [-0.2, 0.35, 0.9], [-0.2, -0.35, 0.9]])
    own, ref = 0.007, 0.009
    r = rng.normal(scale=own, size=(n, 3)) + rng.normal(scale=ref, size=(n, 3)) @ X.T
    r += np.linspace(0.0, 0.05, n)[:, None] * np.array([1.0, -0.5, 0.3])  # a slow misfit
    C = own**2 * np.eye(3) + ref**2 * X @ X.T
    want = C / np.sqrt(np.outer(np.diag(C), np.diag(C)))
    np.testing.assert_allclose(L.shared_noise_correlation(r), want, atol=0.02)
    same = np.repeat(rng.normal(size=(n, 1)), 3, axis=1)  # one noise in every beam
    assert np.linalg.eigvalsh(L.shared_noise_correlation(same))[0] >= L.OWN_NOISE_MIN_SHARE - 1e-9
    w = L.epoch_whitener(np.sqrt(np.diag(C)), want)
    z = w(r[:, :] - r.mean(axis=0)).reshape(-1, 3)
    np.testing.assert_allclose(np.corrcoef(np.diff(z, axis=0).T), np.eye(3), atol=0.03)


def test_a_library_effect_inside_a_generic_term_is_seen_as_nested():
    """``engine._nested_share``: a constant per beam (the LDV offset) lies whole in a smooth
    function of each beam's input that has a constant of its own; a line in time does not lie in
    a step in time, nor does a constant where the baseline already spans it."""
    from solvers.diagnose.engine import _nested_share, _orth

    rng = np.random.default_rng(3)
    m = 600
    u = rng.normal(size=(m, 3))  # each beam's input
    t = np.linspace(0.0, 1.0, m)

    def per_beam(f):  # (m, 3) of one shape per beam -> columns, epoch-major rows
        cols = []
        for j in range(3):
            c = np.zeros((m, 3))
            c[:, j] = f[:, j] if f.ndim == 2 else f
            cols.append(c.ravel())
        return np.array(cols).T

    base = np.hstack([per_beam(u[:, [i, i, i]] * 1.0) for i in range(3)])  # X v: 9 columns
    Q = _orth(base)
    offset = per_beam(np.ones(m))
    smooth = np.hstack([per_beam(u**p) for p in range(4)])  # 1, u, u², u³ per beam
    assert _nested_share(offset, smooth, Q) > 0.999
    step = per_beam((t > 0.5).astype(float))
    line = per_beam(t)
    assert _nested_share(line, step, Q) < 0.99
    assert _nested_share(offset, per_beam(u**2), _orth(np.hstack([base, offset]))) == 0.0
