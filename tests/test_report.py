"""`station report`: the calibration report as one self-contained HTML page, checked in a
real browser (Debian's headless Chromium: load, dump the DOM, take screenshots and look
at their pixels). Skips the browser part only when chromium is not installed."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import zlib
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from station_run import run_station

from db import Store
from station.capture import read_capture, write_capture

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
# CI (.ci/run) installs chromium and sets this: there the browser test must run, not skip
REQUIRED = "chromium" in os.environ.get("STATION_REQUIRE_TOOLS", "").split()


def _sim(tmp_path, procedure, seed, device, date, options=(), **meta):
    path = tmp_path / f"{procedure}-{seed}.csv"
    # simulated on the day it is then dated (the compass field is IGRF's of that day): the report's
    # figures are the same on any day the suite runs
    day = ["--date", date[:10]]
    r = run_station("simulate", "--procedure", procedure, "--seed", seed, "--out", path, *day, *options)
    assert r.returncode == 0, r.stderr
    cap = read_capture(path)
    cap.meta.update(device=device, date=date, **meta)
    write_capture(path, cap)
    return path


@pytest.fixture(scope="module")
def filled(tmp_path_factory):
    """Three P1 calibrations of one unit a year apart (drift), one of a unit with unlabelled
    positions (gauge-fixed entries), a compass and a gyro run."""
    tmp = tmp_path_factory.mktemp("report")
    db = tmp / "station.db"
    ids = {}
    lab = dict(operator="Ann Lee", place="Lab 2, bench 3", reference_equipment="granite table GT-4 (level 0.01°)")
    for k, seed in enumerate((1, 2, 3)):
        path = _sim(tmp, "accel-tabletop", seed, "IMU-9", f"202{4 + k}-0{k + 1}-15T10:3{k}:00Z", **lab)
        r = run_station("calibrate", path, "--save", "--json", "--db", db, "--operator", "Ann Lee")
        assert r.returncode == 0, r.stderr
        ids[f"p1-{k}"] = json.loads(r.stdout)["calibration_id"]
    # unlabelled positions: the upper-triangular gauge fixes M[1][0], M[2][0], M[2][1] (σ 0, not estimated)
    path = _sim(tmp, "accel-tabletop", 4, "IMU-U", "2026-11-20T08:00:00Z", options=("--option", "label_positions=0"))
    r = run_station("calibrate", path, "--save", "--json", "--db", db)
    assert r.returncode == 0, r.stderr
    ids["p1-upper"] = json.loads(r.stdout)["calibration_id"]
    for proc in ("compass", "gyro-drift"):
        path = _sim(tmp, proc, 7, f"{proc}-unit", "2026-11-21T09:15:00Z")
        r = run_station("calibrate", path, "--save", "--json", "--db", db)
        assert r.returncode == 0, r.stderr
        ids[proc] = json.loads(r.stdout)["calibration_id"]
    return tmp, db, ids


def _report(tmp, db, cal_id) -> tuple[Path, str]:
    out = tmp / f"report-{cal_id}.html"
    r = run_station("report", cal_id, "-o", out, "--db", db)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == str(out)
    return out, out.read_text(encoding="utf-8")


class _Tags(HTMLParser):
    def __init__(self):
        super().__init__()
        self.tags = []

    def handle_starttag(self, tag, attrs):
        self.tags.append((tag, dict(attrs)))


def _table_rows(page: str, table_id: str) -> list[list[str]]:
    body = page.split(f"id='{table_id}'", 1)[1].split("</table>", 1)[0]
    rows = []
    for tr in re.findall(r"<tr>(.*?)</tr>", body, re.DOTALL):
        rows.append(
            [re.sub(r"<[^>]+>", "", c).strip() for c in re.findall(r"<t[dh][^>]*>(.*?)</t[dh]>", tr, re.DOTALL)]
        )
    return rows


def test_report_states_what_a_lab_signs(filled):
    tmp, db, ids = filled
    _, page = _report(tmp, db, ids["p1-2"])
    with Store(str(db)) as s:
        cal = s.calibration(ids["p1-2"])
    # self-contained: no external asset, no script
    p = _Tags()
    p.feed(page)
    for tag, attrs in p.tags:
        assert tag not in ("script", "link", "img", "iframe"), tag
        for key in ("src", "href"):
            assert key not in attrs or attrs[key].startswith("#"), (tag, attrs)
    assert "http://" not in page.replace('xmlns="http://www.w3.org/2000/svg"', "") and "https://" not in page
    for text in (
        "IMU-9",
        "Ann Lee",
        "Lab 2, bench 3",
        "granite table GT-4",
        "CN102636665A",
        "2026-03-15 10:32:00",
        "°C",
        cal["hash"],
        cal["capture_sha256"],
        f"Compared with calibration #{ids['p1-1']}",
    ):
        assert text in page, text
    assert re.search(r"station verify</th><td><span class='ok'>ok</span>", page)
    rows = _table_rows(page, "params")
    assert rows[0][:5] == ["parameter", "value", "u (k=1)", "U (k=2)", "unit"]
    by_name = {r[0]: r for r in rows[1:]}
    assert set(by_name) == {f"B[{i}]" for i in range(3)} | {f"M[{i}][{j}]" for i in range(3) for j in range(3)}
    for name, r in by_name.items():
        u = (
            cal["uncertainty"]["B"][int(name[2])]
            if name.startswith("B")
            else cal["uncertainty"]["M"][int(name[2])][int(name[5])]
        )
        assert float(r[2]) == pytest.approx(u, rel=0.05) and float(r[3]) == pytest.approx(2 * u, rel=0.05)
        assert r[4] == ("m/s^2" if name.startswith("B") else "m/s^2 per V")
        assert r[5] != "—"  # the previous calibration's value
    assert page.count("<svg") == 3  # residuals per position, drift of B, drift of M
    assert "Drift history of B" in page and "Residual per position" in page


def test_report_time_axis_and_figures_per_procedure(filled):
    tmp, db, ids = filled
    _, page = _report(tmp, db, ids["p1-2"])
    drift_svg = page.split("Drift history of B")[0].rsplit("<svg", 1)[1]
    years = {int(y) for y in re.findall(r">(\d{4})-\d\d(?:-\d\d)?<", drift_svg)}
    assert years and years <= {2024, 2025, 2026}, years  # the calibrations' own years, not 1013..3040
    _, compass = _report(tmp, db, ids["compass"])
    assert "Coverage: calibrated field directions" in compass and compass.count("<svg") == 1
    assert "nT per uT" in compass
    _, gyro = _report(tmp, db, ids["gyro-drift"])
    assert "Allan deviation" in gyro and "rad/s" in gyro


def test_report_refuses_an_unknown_calibration_and_a_missing_folder(filled, tmp_path):
    _, db, ids = filled
    r = run_station("report", 999, "--db", db, "-o", tmp_path / "x.html")
    assert r.returncode == 2 and "no calibration 999" in r.stderr and r.stderr.count("\n") == 1
    r = run_station("report", ids["compass"], "--db", db, "-o", tmp_path / "no" / "x.html")
    assert r.returncode == 2 and "folder does not exist" in r.stderr
    assert not list(tmp_path.iterdir())


# ------------------------------------------------------------------- the browser


def _png_rgb(data: bytes) -> np.ndarray:
    """Decode an 8-bit RGB/RGBA non-interlaced PNG (what Chromium writes) to HxWx3."""
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    pos, idat, width = 8, b"", None
    while pos < len(data):
        n = int.from_bytes(data[pos : pos + 4], "big")
        kind, body = data[pos + 4 : pos + 8], data[pos + 8 : pos + 8 + n]
        if kind == b"IHDR":
            width, height = int.from_bytes(body[:4], "big"), int.from_bytes(body[4:8], "big")
            depth, ctype, interlace = body[8], body[9], body[12]
            assert depth == 8 and ctype in (2, 6) and interlace == 0, (depth, ctype, interlace)
            bpp = 3 if ctype == 2 else 4
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    raw = np.frombuffer(zlib.decompress(idat), np.uint8).reshape(height, 1 + width * bpp)
    out = np.zeros((height, width * bpp), np.int32)
    prev = np.zeros(width * bpp, np.int32)
    for y in range(height):
        f, line = raw[y, 0], raw[y, 1:].astype(np.int32)
        if f == 0:
            cur = line
        elif f == 2:
            cur = (line + prev) & 255
        else:
            cur = np.zeros_like(line)
            for x in range(width * bpp):
                a = cur[x - bpp] if x >= bpp else 0
                b = prev[x]
                c = prev[x - bpp] if x >= bpp else 0
                if f == 1:
                    p = a
                elif f == 3:
                    p = (a + b) >> 1
                else:
                    pa, pb, pc = abs(b - c), abs(a - c), abs(a + b - 2 * c)
                    p = a if pa <= pb and pa <= pc else (b if pb <= pc else c)
                cur[x] = (line[x] + p) & 255
        out[y] = cur
        prev = cur
    return out.reshape(height, width, bpp)[:, :, :3]


def _chromium(tmp: Path, url: str, *args: str) -> subprocess.CompletedProcess:
    profile = tmp / "chromium-profile"
    return subprocess.run(
        [
            CHROMIUM,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            f"--user-data-dir={profile}",
            *args,
            url,
        ],
        capture_output=True,
        text=True,
        timeout=180,
        check=False,
        cwd=tmp,
    )


@pytest.mark.skipif(CHROMIUM is None and not REQUIRED, reason="chromium is not installed (apt-get install chromium)")
def test_report_renders_in_headless_chromium(filled):
    assert CHROMIUM is not None, "STATION_REQUIRE_TOOLS names chromium, but it is not installed"
    tmp, db, ids = filled
    out, page = _report(tmp, db, ids["p1-2"])
    # 1. the browser loads the whole page: every section and figure is in its DOM
    r = _chromium(tmp, out.as_uri(), "--dump-dom")
    assert r.returncode == 0, r.stderr[-2000:]
    dom = r.stdout
    for section in (
        "Device and procedure",
        "Who, where, when",
        "Parameters",
        "Previous calibration and drift",
        "Figures",
        "Record and integrity",
        "Approval",
    ):
        assert f">{section}</h2>" in dom, section
    assert dom.count("<svg") == 3 and dom.count("<figcaption>") == 3
    # 2. each figure, alone on a page, draws: coloured marks on white (the plots' palette
    # is the only colour there), axes and labels in grey/black
    svgs = re.findall(r"<svg.*?</svg>", page, re.DOTALL)
    for i, svg in enumerate(svgs):
        one = tmp / f"fig{i}.html"
        one.write_text(
            f"<!DOCTYPE html><html><body style='margin:0;background:#fff'>{svg}</body></html>", encoding="utf-8"
        )
        shot = tmp / f"fig{i}.png"
        r = _chromium(tmp, one.as_uri(), f"--screenshot={shot}", "--window-size=700,300", "--hide-scrollbars")
        assert r.returncode == 0 and shot.exists(), r.stderr[-2000:]
        img = _png_rgb(shot.read_bytes())
        spread = img.max(axis=2) - img.min(axis=2)
        coloured = int((spread > 60).sum())
        dark = int((img.max(axis=2) < 100).sum())
        assert coloured > 300, (i, coloured)  # bars / lines / points in the palette
        assert dark > 300, (i, dark)  # tick labels and axis titles
    # 3. the page itself, first screen: not blank, text and the verdict badge drawn
    shot = tmp / "page.png"
    r = _chromium(tmp, out.as_uri(), f"--screenshot={shot}", "--window-size=900,700", "--hide-scrollbars")
    assert r.returncode == 0 and shot.exists(), r.stderr[-2000:]
    img = _png_rgb(shot.read_bytes())
    assert (img.max(axis=2) < 100).mean() > 0.01  # text covers more than 1 % of the first screen
    assert img[:60].std() > 10  # the title is there
    # 4. as the browser builds it, a σ the gauge fixes (not estimated) reads "—" in u and U, as on
    # the Results screen; it read "0", as if exact
    out, _ = _report(tmp, db, ids["p1-upper"])
    r = _chromium(tmp, out.as_uri(), "--dump-dom")
    assert r.returncode == 0, r.stderr[-2000:]
    cells = _sigma_cells(r.stdout.replace('id="params"', "id='params'"))
    zero, estimated = _not_estimated(db, ids["p1-upper"])
    assert zero and estimated
    assert {cells[n] for n in zero} == {("—", "—")}, cells
    assert all(float(cells[n][0]) > 0 for n in estimated), cells


@pytest.mark.skipif(CHROMIUM is None and not REQUIRED, reason="chromium is not installed (apt-get install chromium)")
def test_report_shows_p4_and_the_compass_in_the_units_of_the_screens_in_chromium(filled):
    """The page as the browser builds it: P4's drift in °/h and the compass's soft iron as a
    ratio (uT/uT), as on the Results screen (it said rad/s and nT per uT); the stored
    result keeps its units, and the page says which."""
    import math

    assert CHROMIUM is not None, "STATION_REQUIRE_TOOLS names chromium, but it is not installed"
    tmp, db, ids = filled
    deg_h = math.pi / 648000.0  # 1 °/h in rad/s
    for proc, block, factor, unit, stored in (
        ("gyro-drift", "drift", 1.0 / deg_h, "°/h", "rad/s"),
        ("compass", "soft_iron", 1e-3, "uT/uT", "nT per uT"),
    ):
        out, _ = _report(tmp, db, ids[proc])
        r = _chromium(tmp, out.as_uri(), "--dump-dom")
        assert r.returncode == 0, r.stderr[-2000:]
        dom = r.stdout.replace('id="params"', "id='params'")
        rows = _table_rows(dom, "params")
        by_name = {row[0]: row for row in rows[1:]}
        with Store(str(db)) as s:
            cal = s.calibration(ids[proc])
        values = np.asarray(cal["params"][block], float).ravel()
        sigmas = np.asarray(cal["uncertainty"][block], float).ravel()
        names = [n for n in by_name if n.startswith(block + "[")]
        assert len(names) == len(values), names
        for name, v, s_ in zip(names, values, sigmas):
            row = by_name[name]
            assert row[4] == unit, row
            assert float(row[1]) == pytest.approx(v * factor, rel=1e-6, abs=1e-9)
            if s_ > 0:
                assert float(row[2]) == pytest.approx(s_ * factor, rel=0.05)
        text = re.sub(r"<[^>]+>", " ", dom)
        assert f"{block} in {stored}" in " ".join(text.split())  # what the JSON and exports keep
        if proc == "gyro-drift":
            res = re.search(r"Residual RMS (\S+) (\S+) per sample ·", " ".join(text.split()))
            assert res and res.group(2) == "°/h"
            assert float(res.group(1)) == pytest.approx(cal["residual_rms"] / deg_h, rel=1e-3)
            assert not [row for row in rows[1:] if "rad/s" in row[4]]


def _sigma_cells(page: str) -> dict[str, tuple[str, str]]:
    """parameter -> (u, U) as the params table shows them."""
    return {r[0]: (r[2], r[3]) for r in _table_rows(page, "params")[1:]}


def _not_estimated(db, cal_id) -> tuple[set, set]:
    """(names whose stored σ is exactly 0, names with a σ > 0) of a P1 calibration's M and B."""
    with Store(str(db)) as s:
        u = s.calibration(cal_id)["uncertainty"]
    sig = {f"B[{i}]": u["B"][i] for i in range(3)} | {f"M[{i}][{j}]": u["M"][i][j] for i in range(3) for j in range(3)}
    return {n for n, v in sig.items() if v == 0}, {n for n, v in sig.items() if v > 0}


def test_report_shows_a_sigma_that_is_not_estimated_as_a_dash(filled):
    """A σ of exactly 0 is an entry the gauge fixes (not estimated): the page printed u "0" and
    U "0", read as exact; it shows "—" as the Results screen does (one rule, station.formatting)."""
    from station.formatting import sigma

    tmp, db, ids = filled
    _, page = _report(tmp, db, ids["p1-upper"])
    zero, estimated = _not_estimated(db, ids["p1-upper"])
    assert zero == {"M[1][0]", "M[2][0]", "M[2][1]"}  # the upper-triangular gauge's entries
    cells = _sigma_cells(page)
    for name in zero:
        assert cells[name] == ("—", "—"), (name, cells[name])
    for name in estimated:
        u, U = cells[name]
        assert float(u) > 0 and float(U) == pytest.approx(2 * float(u), rel=0.1), (name, u, U)
    # the same rule as the Results screen's σ column and the text of `station calibrate`
    assert sigma(0.0) == sigma(0) == "—" and sigma(2.5e-4) == "0.00025" and sigma(float("nan")) == "—"


def test_history_and_recompute_show_a_sigma_that_is_not_estimated_as_a_dash(filled):
    """`station history` printed the gauge-fixed entries as `0±0` and `station recompute` a ±SIGMA
    of 0: read as exact. Both now say "—" there, as the report and the Results screen do."""
    tmp, db, ids = filled
    r = run_station("history", "IMU-U", "--db", db)
    assert r.returncode == 0, r.stderr
    m_line = next(x for x in r.stdout.splitlines() if x.lstrip().startswith("M"))
    pairs = re.findall(r"(\S+)±(\S+)", m_line)
    assert len(pairs) == 9, m_line
    assert [s for _, s in pairs].count("—") == 3, m_line  # M[1][0], M[2][0], M[2][1]
    assert all(s == "—" or float(s) > 0 for _, s in pairs), m_line
    r = run_station("recompute", str(ids["p1-upper"]), "--db", db)
    assert r.returncode == 0, r.stderr
    rows = {x.split()[0]: x.split() for x in r.stdout.splitlines() if x.startswith("M[")}
    for name in ("M[1][0]", "M[2][0]", "M[2][1]"):
        assert rows[name][2] == "-", rows[name]
    assert float(rows["M[0][0]"][2]) > 0


def test_history_on_an_80_column_terminal_wraps_between_pairs(filled):
    """On an 80-column terminal `station history` printed a P1 M as one 175-column line that the
    terminal broke mid-number; it wraps between value±σ pairs, indented (into a pipe, one line:
    the test above reads it so)."""
    import os

    from tests.test_terminal_safety import _pty_run

    tmp, db, ids = filled
    env = {**os.environ, "COLUMNS": "80", "LINES": "24"}
    rc, out = _pty_run("history", "IMU-U", "--db", db, env=env)
    text = out.decode("utf-8")
    assert rc == 0, text
    lines = text.splitlines()
    assert max(len(x) for x in lines) <= 80, max(lines, key=len)
    i = next(k for k, x in enumerate(lines) if x.lstrip().startswith("M "))
    block = [lines[i]] + [x for x in lines[i + 1 : i + 4] if x.startswith("        ")]
    pairs = re.findall(r"(\S+)±(\S+)", " ".join(block))
    assert len(pairs) == 9, block  # every pair whole, none split across lines


def test_the_captures_operator_is_the_reports_operator_unless_another_is_given(tmp_path):
    """README: the report's operator comes from the capture's `operator` (the TUI's Connect
    screen, `record --meta operator=...` write it). `calibrate FILE --save` without --operator
    stored the login name instead (save_result put getpass.getuser() before the capture's
    value), so a bench PC's shared login signed every CLI-saved report. --operator still wins;
    the login is the fallback only where the capture names nobody."""
    import getpass

    db = tmp_path / "station.db"
    path = _sim(tmp_path, "compass", 7, "MAG-OP", "2026-11-21T09:15:00Z", operator="Ann Lee")
    r = run_station("calibrate", path, "--save", "--json", "--db", db)
    assert r.returncode == 0, r.stderr
    cal_id = json.loads(r.stdout)["calibration_id"]
    history = json.loads(run_station("history", "MAG-OP", "--json", "--db", db).stdout)
    assert history[-1]["operator"] == "Ann Lee", history[-1].get("operator")
    _, page = _report(tmp_path, db, cal_id)
    assert "Ann Lee" in page
    if getpass.getuser() != "Ann Lee":
        assert f"<td>{getpass.getuser()}</td>" not in page
    other = _sim(tmp_path, "compass", 8, "MAG-OP", "2026-11-22T09:15:00Z", operator="Ann Lee")
    r = run_station("calibrate", other, "--save", "--json", "--db", db, "--operator", "Bo Chen")
    assert r.returncode == 0, r.stderr
    assert json.loads(run_station("history", "MAG-OP", "--json", "--db", db).stdout)[-1]["operator"] == "Bo Chen"
