"""P1 level-table calibration: recovery of simulated truth within the reported σ over many
seeds, the two stages, the gauge, unsupportable captures refused with the reason."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from solvers import tabletop as T
from solvers.frames import rotvec_to_matrix
from solvers.models import accel
from solvers.positions import P1_POSITIONS, C_n_b_for
from solvers.simulate import nominal_tabletop_device, placement_error, simulate
from station.capture import Capture, write_capture
from station.cli import main

G = 9.80152


def fast_table(seed: int, *, noise_mps2=0.01, n=2000, placement_deg=0.5, tilted_deg=3.0, tilt_deg=0.5, names=None):
    """A P1 table of averages straight from the forward model (the simulator's bench, without
    its time series): placement error per position, a tilted table, white noise."""
    rng = np.random.default_rng(seed)
    dev = nominal_tabletop_device(rng)
    K = accel.K_matrix(dev)
    axis = rng.normal(size=3) * [1, 1, 0]
    tilt = rotvec_to_matrix(axis / np.linalg.norm(axis) * math.radians(tilt_deg))
    out = []
    for name in names or list(P1_POSITIONS):
        big = name[:2] in ("xy", "yz", "xz")
        C = (
            tilt
            @ C_n_b_for(P1_POSITIONS[name], rng.uniform(0, 2 * math.pi))
            @ placement_error(rng, tilted_deg if big else placement_deg)
        )
        f = C.T @ np.array([0.0, 0.0, -G])
        V = accel.forward(f[None], dev)[0] + K @ rng.normal(scale=noise_mps2 / math.sqrt(n), size=3)
        std = noise_mps2 * np.linalg.norm(K, axis=1)
        d, s = T.known_direction(name)
        out.append(T.Position(name, V, std, n, direction=d, placement_sigma_rad=s))
    B, M = accel.forward_to_p1(dev)
    return out, B, M


def z_scores(res, B, M):
    return np.r_[(res.B - B) / res.sigma_B, ((res.M - M) / res.sigma_M).ravel()]


def test_coverage_over_200_seeds():
    """About 68 % of the errors within 1σ and 95 % within 2σ (binomial tolerance for 200
    seeds, 4 standard deviations: ±0.13 and ±0.06)."""
    z, flagged = [], 0
    for seed in range(200):
        pos, B, M = fast_table(seed)
        r = T.calibrate(pos, G)
        z.append(z_scores(r, B, M))
        flagged += len(r.outliers)
    z = np.array(z)
    assert flagged <= 4  # no position is off: a false alarm is rare
    in1, in2 = np.mean(np.abs(z) < 1), np.mean(np.abs(z) < 2)
    assert abs(in1 - 0.683) < 0.13, in1
    assert abs(in2 - 0.954) < 0.06, in2
    # and per parameter not wildly off (each has 200 samples: ±4σ = ±0.13)
    assert np.all(np.abs(np.mean(np.abs(z) < 1, axis=0) - 0.683) < 0.15)


def test_stage8_and_stage10_agree_without_placement_error():
    """With perfect placement both stages see the same truth: step 10 = step 8 within
    step 8's noise-limited error (the tiny sensor noise only)."""
    pos, B, M = fast_table(1, placement_deg=0.0, tilted_deg=0.0, tilt_deg=0.0, noise_mps2=1e-4)
    for p in pos:  # the operator is known to be perfect here
        p.placement_sigma_rad = 1e-5
    r = T.calibrate(pos, G)
    assert np.allclose(r.step8["B"], r.B, atol=1e-4)  # m/s²: 1e-4 noise / sqrt(2000) × leverage
    assert np.allclose(r.step8["M"], r.M, atol=1e-5)
    assert np.allclose(r.B, B, atol=1e-4) and np.allclose(r.M, M, atol=1e-5)


def test_stage10_beats_stage8_with_placement_error():
    """Placement errors spoil step 8's norm residual; step 10 brings it to the noise, and the
    two agree within step 8's (placement-limited) uncertainty."""
    pos, B, M = fast_table(2)
    r = T.calibrate(pos, G)
    V = np.array([p.mean for p in pos])
    r8 = np.linalg.norm(accel.p1_apply(V, r.step8["B"], r.step8["M"]), axis=1) - G
    assert np.sqrt(np.mean(r8**2)) > 20 * r.residual_rms
    assert r.residual_rms < 1e-3  # noise 0.01/sqrt(2000) = 2.2e-4 m/s²
    assert np.all(np.abs(r.step8["M"] - r.M) < 4 * r.step8["sigma_M"])


def test_gauges_describe_the_same_calibration():
    """The upper-triangular result is the table result rotated."""
    pos, B, M = fast_table(3)
    rt = T.calibrate(pos, G, gauge="table")
    ru = T.calibrate(pos, G, gauge="upper-triangular")
    assert ru.gauge == "upper-triangular" and np.allclose(np.tril(ru.M, -1), 0.0)
    Bu, Mu = T.to_upper(rt.B, rt.M)
    # the table result also carries the removal of the rotation's second-order bias
    # (M_ii·tr Σ_ω/2 ~ 1e-5 relative), so agreement is to within 1σ, not exactly
    up = np.triu(np.ones((3, 3), bool))
    assert np.all(np.abs(Mu - ru.M)[up] < ru.sigma_M[up])
    assert np.all(np.abs(Bu - ru.B) < ru.sigma_B)


def test_any_number_of_positions_from_nine():
    pos, B, M = fast_table(4, names=list(P1_POSITIONS)[:6] + ["xy_45", "yz_45", "xz_45"])
    r = T.calibrate(pos, G)
    assert r.n_distinct == 9
    assert np.all(np.abs(z_scores(r, B, M)) < 5)


def test_nine_positions_say_the_residual_checks_nothing():
    """docs/protocol.md's example (`sim-device --auto`, `record --seconds 120`) records 9 holds:
    9 norm rows for the norm's 9 parameters, and `calibrate` printed "residual 2.51e-15 m/s^2 RMS"
    with no word that a zero residual is all 9 rows can give. It says so; with 10 it does not."""
    names = list(P1_POSITIONS)[:6] + ["xy_45", "yz_45", "xz_45"]
    for labelled in (True, False):
        pos, _, _ = fast_table(4, names=names)
        if not labelled:
            for p in pos:
                p.direction = None
        r = T.calibrate(pos, G)
        said = [w for w in r.warnings if "no degree of freedom" in w]
        assert len(said) == 1 and said[0].startswith("9 positions for the norm condition's 9 parameters"), r.warnings
    pos, _, _ = fast_table(4, names=names + ["xz_135"])
    assert not any("no degree of freedom" in w for w in T.calibrate(pos, G).warnings)


def test_one_position_far_off_is_named():
    """With redundancy (each P1 position twice) a position 0.01 m/s² off (~45σ) is named;
    with none off, none is."""
    pos, B, M = fast_table(5, names=list(P1_POSITIONS) * 2)
    assert T.calibrate(pos, G).outliers == []
    pos[7].mean = pos[7].mean * 1.001
    r = T.calibrate(pos, G)
    assert r.outliers == [7]
    assert any(pos[7].label in w and "disagrees" in w for w in r.warnings)


def test_too_few_and_too_alike_positions_refused():
    pos, _, _ = fast_table(6, names=list(P1_POSITIONS)[:6])
    with pytest.raises(T.TooFewPositions, match="6 distinct orientations.*six-position"):
        T.calibrate(pos, G)
    assert T.calibrate(pos, G, method="six-position").method == "six-position"
    alike, _, _ = fast_table(7, names=["z_up"] * 12)
    with pytest.raises(T.TooFewPositions, match="1 distinct orientation in"):
        T.calibrate(alike, G)


# ----------------------------------------------------------------------------- the CLI


def _write(tmp_path, sim, name="c.csv", columns=None):
    path = tmp_path / name
    write_capture(path, Capture(dict(sim.meta), dict(columns or sim.columns)))
    return str(path)


def _cli(capsys, *argv):
    code = main(["calibrate", *argv])
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.fixture(scope="module")
def series():
    return simulate("accel-tabletop", seed=11, hold_s=5.0, move_s=2.0)


def test_cli_time_series_labelled_and_unlabelled(tmp_path, capsys, series):
    import json

    path = _write(tmp_path, series)
    code, out, err = _cli(capsys, path, "--json")
    assert code == 0, err
    res = json.loads(out)
    assert res["procedure"] == "accel-tabletop" and res["gauge"] == "table" and res["n_positions"] == 12
    assert [p["label"] for p in res["positions"]] == list(P1_POSITIONS)
    assert all(abs(p["residual_mps2"]) < 0.01 for p in res["positions"])
    M = np.array(series.truth["M"])
    assert np.all(np.abs(np.array(res["params"]["M"]) - M) < 5 * np.array(res["uncertainty"]["M"]))
    cols = {k: v for k, v in series.columns.items() if k != "position"}
    code, out, err = _cli(capsys, _write(tmp_path, series, "u.csv", cols), "--json")
    assert code == 0, err
    res_u = json.loads(out)
    assert res_u["gauge"] == "upper-triangular" and res_u["n_positions"] == 12
    assert res_u["positions_found_by"].startswith("static intervals")
    assert 0.5 < res_u["residual_rms"] / res["residual_rms"] < 2.0  # other spans, same noise


def test_cli_refuses_saturated_axis(tmp_path, capsys, series):
    cols = dict(series.columns)
    az = cols["az"].copy()
    limit = np.percentile(az, 90)
    cols["az"] = np.minimum(az, limit)
    code, out, err = _cli(capsys, _write(tmp_path, series, "sat.csv", cols))
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and "axis z is saturated" in err


def test_cli_refuses_too_few_positions(tmp_path, capsys):
    sim = simulate("accel-tabletop", seed=12, hold_s=3.0, move_s=2.0, positions=list(P1_POSITIONS)[:6])
    path = _write(tmp_path, sim)
    code, out, err = _cli(capsys, path)
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "6 distinct orientations" in err and "at least 9" in err
    code, out, err = _cli(capsys, path, "--method", "six-position")
    assert code == 0 and "six-position" in out


def test_cli_refuses_all_alike(tmp_path, capsys):
    sim = simulate("accel-tabletop", seed=13, hold_s=3.0, move_s=2.0, positions=["z_up", "z_down"] * 5)
    code, out, err = _cli(capsys, _write(tmp_path, sim))
    assert code == 2 and "2 distinct orientations" in err


def test_imucal_ferraris_says_plainly_what_it_supports(shared_data, capsys):
    plain = str(shared_data / "imucal_ferraris" / "imucal_ferraris.capture.csv")
    code, out, err = _cli(capsys, plain)
    assert code == 2 and "distinct orientations" in err and "at least 9" in err
    labelled = str(shared_data / "imucal_ferraris" / "imucal_ferraris_labelled.capture.csv")
    code, out, err = _cli(capsys, labelled)
    assert code == 2 and "--method six-position" in err
    code, out, err = _cli(capsys, labelled, "--method", "six-position")
    assert code == 0 and "six-position" in out


def test_table_without_noise_columns_and_numbered_positions(tmp_path, capsys):
    """A table of averages with positions numbered 1-12 (the source's order for 1-6) and no
    n/*_std: the table gauge still applies, the noise comes from the residuals, and the
    result agrees with the truth within a few of its σ."""
    import json

    sim = simulate("accel-tabletop", seed=14, hold_s=5.0, move_s=2.0, averages=True)
    cols = {
        "position": np.array([str(k + 1) for k in range(12)], dtype=object),
        **{c: sim.columns[c] for c in ("ax", "ay", "az")},
    }
    code, out, err = _cli(capsys, _write(tmp_path, sim, "nonoise.csv", cols), "--json")
    assert code == 0, err
    res = json.loads(out)
    assert res["gauge"] == "table" and res["noise"] == "estimated from the residuals"
    assert any("estimated from the residuals" in w for w in res["warnings"])
    M, sM = np.array(res["params"]["M"]), np.array(res["uncertainty"]["M"])
    assert np.all(np.abs(M - np.array(sim.truth["M"])) < 5 * sM)


def test_a_table_of_averages_with_a_missing_value_is_named_by_its_line(tmp_path):
    """A P1 table of averages with an empty ax was refused as 'file: row 2: ...' with no line
    of the file; a row with an empty n made every later row's n print as 1 and dropped the
    given noise of all rows without saying which row lacked it. Now the line is named."""
    from tests.station_run import assert_one_line_refusal, run_station

    table = tmp_path / "table.csv"
    assert (
        run_station("simulate", "--procedure", "accel-tabletop", "--out", table, "--option", "averages=1").returncode
        == 0
    )
    lines = table.read_text().splitlines()
    header = next(i for i, line in enumerate(lines) if line.startswith("position,"))
    names = lines[header].split(",")
    second = lines[header + 2].split(",")  # line header + 3 of the file

    def with_empty(column):
        row = list(second)
        row[names.index(column)] = ""
        path = tmp_path / f"no_{column}.csv"
        path.write_text("\n".join(lines[: header + 2] + [",".join(row)] + lines[header + 3 :]) + "\n")
        return path

    for command in ("calibrate", "diagnose"):
        assert_one_line_refusal(
            run_station(command, with_empty("ax"), "--json"),
            f"no_ax.csv:{header + 3}: accelerometer average is missing",
        )
    res = run_station("calibrate", with_empty("n"), "--json")
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    assert any(f"(line {header + 3}) without n >= 2" in w for w in out["warnings"]), out["warnings"]
    ns = [p["n"] for p in out["positions"]]
    assert ns[1] == 1 and all(n == int(second[names.index("n")]) for n in ns[2:]), ns


@pytest.mark.parametrize("seed", [14, 15, 16])
def test_a_position_read_far_from_its_label_is_named_as_mislabelled(tmp_path, capsys, seed):
    """A table with y_up's row labelled x_up (a typo, a step recorded twice) was calibrated
    with exit 0; the labels fix the gauge, the fit twisted, and the only word was 'residuals
    29x the noise ... (temperature, non-linearity, moving positions?)'. The row whose reading
    lies far from its label's direction is named; the truly labelled table names none."""
    import json

    sim = simulate("accel-tabletop", seed=seed, hold_s=5.0, move_s=2.0, averages=True)
    res = json.loads(_cli(capsys, _write(tmp_path, sim, "ok.csv"), "--json")[1])
    assert not any("mislabelled" in w for w in res["warnings"]), res["warnings"]
    labels = np.array(sim.columns["position"], dtype=object)
    k = int(np.flatnonzero(labels == "y_up")[0])
    labels[k] = "x_up"
    code, out, err = _cli(capsys, _write(tmp_path, sim, "typo.csv", {**sim.columns, "position": labels}), "--json")
    assert code == 0, err
    said = [w for w in json.loads(out)["warnings"] if "mislabelled" in w]
    assert len(said) == 1 and "x_up" in said[0] and f"row {k + 1}" in said[0], said
