"""`station diagnose` on compass captures written by QA s27d's independent dynamic generator
(benchmarks/indep_s27_dyn_generator.py: written from the contracts alone, its own parts,
motions and noise): what the residual whiteness test sees when no candidate names a slow
structure.

The effect is chosen by the generator's seed and sized by the generator at 10σ of its own
detection z; nothing about it reaches the code but the capture file.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
from station_run import run_station

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import indep_s27_dyn_generator as D  # noqa: E402

pytestmark = pytest.mark.slow


def _diagnosed(tmp_path, seed, effect):
    meta, cols, data, fmts, truth = D.generate_compass(seed, effect, 10.0)
    path = tmp_path / f"s{seed}.csv"
    D._write_capture(path, meta, cols, data, fmts)
    res = run_station("diagnose", path, "--json")
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout), truth


def test_a_bias_swinging_over_seconds_on_slow_holds_is_not_called_white(tmp_path):
    """An AK8963 read at 8 Hz, held still in 12–24 orientations, whose bias swings over a period of
    8–25 s (generator seed 700125: 76 nT against 150 nT of noise). No candidate passes the compass
    bar, and the whiteness test, 20 lags = 2.5 s of rows, gave p 0.08: the report said nothing.
    Lags over 10 s as well see it (p ~ 1e-5)."""
    out, truth = _diagnosed(tmp_path, 700125, "periodic_bias")
    assert (truth["part"], truth["mode"], truth["rate_hz"]) == ("AK8963", "holds", 8.0)
    kinds = [q["kind"] for q in out["quality"]]
    assert out["verdict"] or "residuals_not_white" in kinds, (out["verdict"], kinds)


def test_white_noise_on_slow_holds_stays_white(tmp_path):
    """The same part, rate and kind of bench with no effect (seed 700135): white noise on a
    quantiser of one noise σ is not called correlated by the longer lags (p 0.14 over both tests)."""
    out, truth = _diagnosed(tmp_path, 700135, "none")
    assert (truth["part"], truth["mode"], truth["rate_hz"]) == ("AK8963", "holds", 8.0)
    assert "residuals_not_white" not in [q["kind"] for q in out["quality"]]
    assert out["verdict"] == []
