"""`station diagnose` on P4 gyro-drift captures of the independent static generator
(benchmarks/indep_s27_generator.py, written from the contracts only). The hidden effect's name
goes to the generator only; each test reads the capture file through the real command."""

from __future__ import annotations

import json
import sys

from station_run import ROOT, run_station

SITE = ("latitude_deg", "longitude_deg", "altitude_m")


def _generator():
    if str(ROOT / "benchmarks") not in sys.path:
        sys.path.insert(0, str(ROOT / "benchmarks"))
    import indep_s27_generator

    return indep_s27_generator


def _capture(tmp_path, hidden, seed, z=10.0, site_and_headings=True):
    """The generator's capture; without ``site_and_headings``, as a bench that recorded neither the
    site nor the heading of each position writes it (those metadata lines and the column left out)."""
    path = tmp_path / "capture.csv"
    _generator().make_one("P4", hidden, z, seed, str(path))
    if not site_and_headings:
        out, drop = [], None
        for line in path.read_text().splitlines():
            if line.startswith("#"):
                if not any(line.startswith(f"# {k}:") for k in SITE):
                    out.append(line)
                continue
            cells = line.split(",")
            if drop is None:
                drop = cells.index("heading_deg") if "heading_deg" in cells else -1
            out.append(",".join(c for i, c in enumerate(cells) if i != drop))
        path.write_text("\n".join(out) + "\n")
    return path


def _diagnose(path) -> dict:
    res = run_station("diagnose", path, "--json", "--no-plots")
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout)


def _tied(res: dict, a: str, b: str) -> bool:
    return any({e["name"], c["name"]} == {a, b} for e in res["effects"] for c in e.get("confused_with", []))


def test_p4_earth_rate_without_latitude_or_headings_is_not_named_g_sensitivity_alone(tmp_path):
    """10 positions at rest, no latitude and no heading per position (a plain bias is fitted), the
    Earth rate 10σ above the noise at latitude -6.5° (nearly all of it horizontal). The headings
    were taken as 0, so the Earth-rate candidate fitted a wrong north direction and failed, and
    `g_sensitivity` (9 parameters on 10 positions) was named alone. The Earth rate in body axes has
    the magnitude Ω at every orientation; a G f within what it can make is tied to it."""
    res = _diagnose(_capture(tmp_path, "earth_rate", 702001))
    assert "earth_rate" in res["verdict"], (res["verdict"], res["candidates"])
    if "g_sensitivity" in res["verdict"]:
        assert _tied(res, "earth_rate", "g_sensitivity"), res["effects"]


def test_p4_earth_rate_up_part_without_headings_is_tied_to_g_sensitivity(tmp_path):
    """14 positions at latitude 58°, the Earth rate at 10σ, neither site nor headings recorded: its
    up part in body axes is Ω sin(lat) f/|f|, an isotropic G f. `earth_rate` was named alone (fitted
    with every heading taken as 0); g_sensitivity explains the same and must be named beside it."""
    res = _diagnose(_capture(tmp_path, "earth_rate", 705001, site_and_headings=False))
    assert "earth_rate" in res["verdict"], (res["verdict"], res["candidates"])
    assert _tied(res, "earth_rate", "g_sensitivity"), res["effects"]


def test_p4_g_sensitivity_far_above_the_earth_rate_is_not_tied_to_it(tmp_path):
    """A gyro bias proportional to the specific force at 30σ (a G f of some 10⁻³ rad/s, tens of
    times the Earth rate), 9 positions, neither site nor headings recorded: the Earth rate cannot
    make a G f that large, so g_sensitivity is named without `earth_rate` beside it (a guard of the
    tie above: it passes before the change too)."""
    res = _diagnose(_capture(tmp_path, "g_sensitivity", 704001, z=30.0, site_and_headings=False))
    assert "g_sensitivity" in res["verdict"], (res["verdict"], res["candidates"])
    assert "earth_rate" not in res["verdict"], res["effects"]
