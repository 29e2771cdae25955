"""An independent reading of ../shared/spec: capture-format.md, calibrate.md and diagnose.md.

Written from the spec's text alone, not from the station's code: a capture is parsed here with
nothing but the standard library, and the JSON of `calibrate --json` and `diagnose --json` is
checked field by field against the spec's tables. Each function returns the list of the spec's
statements the input breaks (empty when it keeps them all), so a test can print every one.
"""

from __future__ import annotations

import datetime as dt
import json
import math
import re

# capture-format.md, "Metadata keys"
PROCEDURES = ("accel-tabletop", "accel-centrifuge", "compass", "gyro-drift", "ldv")
NUMERIC_KEYS = ("latitude_deg", "longitude_deg", "altitude_m", "g_mps2", "radius_m", "heading_deg", "sample_rate_hz")
# the units the spec names for each unit key ("e.g.": the list is not closed, but a station-written file keeps to it)
UNITS = {
    "accel_unit": {"V", "counts", "g", "m/s^2"},
    "gyro_unit": {"V", "counts", "rad/s", "deg/s"},
    "mag_unit": {"V", "counts", "nT", "uT", "gauss"},
}
# capture-format.md, "Columns"
SPEC_COLUMNS = {
    "t", "position", "ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz", "temp_c", "speed_rad_s",
    "ref_gx", "ref_gy", "ref_gz", "vl1", "vl2", "vl3", "vx", "vy", "vz", "vn", "ve", "vd",
    "roll_deg", "pitch_deg", "yaw_deg", "wx", "wy", "wz", "heading_deg", "n",
}  # fmt: skip
# "`.` as decimal mark": a plain decimal number, optionally with an exponent
NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")


def parse_capture(raw: bytes) -> tuple[dict[str, str], list[str], list[list[str]], list[str]]:
    """(metadata, header, rows as text fields, problems) of a capture's bytes, as the spec lays it out."""
    problems: list[str] = []
    text = raw.decode("utf-8")
    if text.startswith("\ufeff"):
        problems.append("byte-order mark before '# station-capture: 1'")
        text = text[1:]
    lines = text.split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    else:
        problems.append("last line has no line end")
    crlf = [ln.endswith("\r") for ln in lines]
    if any(crlf) and not all(crlf):
        problems.append("line endings mix LF and CRLF")
    lines = [ln[:-1] if ln.endswith("\r") else ln for ln in lines]
    if any("\r" in ln for ln in lines):
        problems.append("carriage return inside a line")
    meta: dict[str, str] = {}
    if not lines or lines[0].strip() != "# station-capture: 1":
        problems.append(f"first line is {lines[0][:40]!r}, not '# station-capture: 1'" if lines else "empty")
        return meta, [], [], problems
    i = 1
    while i < len(lines) and lines[i].startswith("#"):
        key, sep, value = lines[i][1:].partition(":")
        if not sep or not key.strip():
            problems.append(f"line {i + 1}: metadata line without 'key: value'")
        elif key.strip() in meta:
            problems.append(f"line {i + 1}: metadata key {key.strip()!r} twice")
        else:
            meta[key.strip()] = value.strip()
        i += 1
    if i >= len(lines):
        problems.append("no header row")
        return meta, [], [], problems
    header = [c.strip() for c in lines[i].split(",")]
    if len(set(header)) != len(header) or not all(header):
        problems.append(f"line {i + 1}: header has empty or repeated names: {header}")
    rows = []
    for j, ln in enumerate(lines[i + 1 :], i + 2):
        fields = ln.split(",")
        if len(fields) != len(header):
            problems.append(f"line {j}: {len(fields)} fields, header has {len(header)}")
            continue
        rows.append(fields)
    if not rows:
        problems.append("no data rows")
    return meta, header, rows, problems


def check_capture(raw: bytes, *, written_by_station: bool = True) -> list[str]:
    """The statements of capture-format.md that a capture's bytes break."""
    meta, header, rows, problems = parse_capture(raw)
    if not header:
        return problems
    proc = meta.get("procedure")
    if proc not in PROCEDURES:
        problems.append(f"procedure {proc!r} is not one of {PROCEDURES}")
    for key in NUMERIC_KEYS:
        if key in meta and not (NUMBER.fullmatch(meta[key]) and math.isfinite(float(meta[key]))):
            problems.append(f"metadata {key}: {meta[key]!r} is not a number")
    if "latitude_deg" in meta and NUMBER.fullmatch(meta["latitude_deg"]) and abs(float(meta["latitude_deg"])) > 90:
        problems.append("latitude_deg beyond ±90")
    if "sample_rate_hz" in meta and NUMBER.fullmatch(meta["sample_rate_hz"]) and float(meta["sample_rate_hz"]) <= 0:
        problems.append("sample_rate_hz not positive")
    if "date" in meta:
        try:
            dt.datetime.fromisoformat(meta["date"])
        except ValueError:
            problems.append(f"date {meta['date']!r} is not ISO")
    if meta.get("gyro_mode") not in (None, "reference", "static"):
        problems.append(f"gyro_mode {meta['gyro_mode']!r}")
    if written_by_station:
        for key, allowed in UNITS.items():
            if key in meta and meta[key] not in allowed:
                problems.append(f"{key} {meta[key]!r} is none of the spec's spellings {sorted(allowed)}")
    col = {name: k for k, name in enumerate(header)}
    for name, k in col.items():
        if name == "position":
            continue  # an integer or a label
        for j, r in enumerate(rows):
            v = r[k].strip()
            if v and not NUMBER.fullmatch(v):
                problems.append(f"row {j + 1}, column {name!r}: {v!r} is not a number with '.' as decimal mark")
                break
    if "t" in col:  # a time series: t in seconds, non-decreasing
        t = [float(r[col["t"]]) for r in rows if r[col["t"]].strip()]
        if len(t) != len(rows):
            problems.append("a row of the time series has no t")
        if any(b < a for a, b in zip(t, t[1:])):
            problems.append("t decreases")
        if "sample_rate_hz" in meta and len(t) > 10 and NUMBER.fullmatch(meta["sample_rate_hz"]):
            steps = sorted(b - a for a, b in zip(t, t[1:]))
            step = steps[len(steps) // 2]
            rate = float(meta["sample_rate_hz"])
            if step > 0 and not 0.8 < rate * step < 1.25:
                problems.append(f"sample_rate_hz {rate} against t's median step {step} s")
    else:  # a table of averages: optional n (samples averaged) and <col>_std
        if "n" in col:
            for r in rows:
                v = r[col["n"]].strip()
                if v and not (NUMBER.fullmatch(v) and float(v) >= 1 and float(v) == int(float(v))):
                    problems.append(f"n {v!r} is not a sample count")
                    break
        for name in header:
            if name.endswith("_std") and name[:-4] in col:
                if any(r[col[name]].strip() and float(r[col[name]]) < 0 for r in rows):
                    problems.append(f"{name} negative")
    need = {
        "accel-tabletop": [("ax", "ay", "az")],
        "accel-centrifuge": [("ax", "ay", "az", "speed_rad_s")],
        "compass": [("mx", "my", "mz")],
        "gyro-drift": [("gx", "gy", "gz")],
        "ldv": [("vl1", "vl2", "vl3")],
    }.get(proc, [])
    for names in need:
        if not set(names) <= set(col):
            problems.append(f"{proc}: columns {names} missing")
    if proc == "ldv" and not (
        {"vx", "vy", "vz"} <= set(col) or {"vn", "ve", "vd", "roll_deg", "pitch_deg", "yaw_deg"} <= set(col)
    ):
        problems.append("ldv: neither vx vy vz nor vn ve vd with roll_deg pitch_deg yaw_deg")
    if proc == "gyro-drift" and meta.get("gyro_mode") == "reference" and not {"ref_gx", "ref_gy", "ref_gz"} <= set(col):
        problems.append("gyro-drift mode reference without ref_gx ref_gy ref_gz")
    return problems


def columns(raw: bytes) -> tuple[dict[str, str], dict[str, list[float]]]:
    """Metadata and numeric columns (missing values as nan; `position` left out)."""
    meta, header, rows, _ = parse_capture(raw)
    out = {}
    for k, name in enumerate(header):
        if name != "position":
            out[name] = [float(r[k]) if r[k].strip() else math.nan for r in rows]
    return meta, out


# ------------------------------------------------------------------------------- calibrate.md


def _reject_constant(name):
    raise ValueError(f"{name} is not JSON")


def one_json_object(stdout: str) -> tuple[dict | None, list[str]]:
    """stdout as the spec's `--json` gives it: one JSON object and nothing else (no NaN/Infinity)."""
    try:
        d = json.loads(stdout, parse_constant=_reject_constant)
    except ValueError as exc:
        return None, [f"stdout is not one JSON object: {exc}"]
    if not isinstance(d, dict):
        return None, ["stdout's JSON is not an object"]
    return d, []


def _num(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _vec(x, n=3) -> bool:
    return isinstance(x, list) and len(x) == n and all(_num(v) for v in x)


def _mat(x) -> bool:
    return isinstance(x, list) and len(x) == 3 and all(_vec(r) for r in x)


def _shape_problems(p, s, where: str) -> list[str]:
    """`uncertainty` holds the 1σ of each parameter in `params`, same shape."""
    if isinstance(p, dict):
        if not isinstance(s, dict) or set(s) != set(p):
            return [f"uncertainty{where}: keys differ from params{where}"]
        return [q for k in p for q in _shape_problems(p[k], s[k], f"{where}.{k}")]
    if isinstance(p, list):
        if not isinstance(s, list) or len(s) != len(p):
            return [f"uncertainty{where}: not a list of params{where}'s length"]
        return [q for i, (a, b) in enumerate(zip(p, s)) for q in _shape_problems(a, b, f"{where}[{i}]")]
    if _num(p) and not (s is None or (_num(s) and s >= 0)):
        return [f"uncertainty{where} = {s!r} is no standard deviation"]
    return []


def check_calibrate(d: dict, procedure: str) -> list[str]:
    """The statements of calibrate.md that one `calibrate --json` object breaks."""
    pr: list[str] = []
    for key in ("procedure", "device", "model", "params", "uncertainty", "residual_rms", "n_positions", "warnings"):
        if key not in d:
            pr.append(f"no '{key}'")
    if pr:
        return pr
    if d["procedure"] != procedure:
        pr.append(f"procedure {d['procedure']!r}, capture says {procedure!r}")
    if not (isinstance(d["device"], str) and d["device"]):
        pr.append("device is not a non-empty string")
    if not isinstance(d["model"], str):
        pr.append("model is not a string")
    if not (_num(d["residual_rms"]) and d["residual_rms"] >= 0):
        pr.append(f"residual_rms {d['residual_rms']!r}")
    if not (isinstance(d["n_positions"], int) and not isinstance(d["n_positions"], bool) and d["n_positions"] > 0):
        pr.append(f"n_positions {d['n_positions']!r}")
    if not (isinstance(d["warnings"], list) and all(isinstance(w, str) for w in d["warnings"])):
        pr.append("warnings is not a list of strings")
    p, s = d["params"], d["uncertainty"]
    if not isinstance(p, dict) or not isinstance(s, dict):
        return [*pr, "params/uncertainty are not objects"]
    numeric = {k: v for k, v in p.items() if not isinstance(v, str)}  # gyro-drift's `mode` has no σ
    pr += _shape_problems(numeric, {k: s.get(k) for k in numeric}, "")
    if procedure == "accel-tabletop":
        if not (_vec(p.get("B")) and _mat(p.get("M"))):
            pr.append("accel-tabletop: B [3] and M [3x3] expected")
        # "the JSON also says which gauge fixes the rotation the norm cannot see"
        if not any(isinstance(v, str) and v for k, v in d.items() if "gauge" in k):
            pr.append("accel-tabletop: no gauge named")
    elif procedure == "accel-centrifuge":
        if not all(_vec(p.get(k)) for k in ("S", "b", "D")):
            pr.append("accel-centrifuge: S, b, D [3] expected")
        if "gamma" in p and not (isinstance(p["gamma"], list) and len(p["gamma"]) == 6):
            pr.append("accel-centrifuge: gamma is not [6]")
    elif procedure == "compass":
        if not (_vec(p.get("hard_iron")) and _mat(p.get("soft_iron"))):
            pr.append("compass: hard_iron [3] and soft_iron [3x3] expected")
        elif any(p["soft_iron"][i][j] != 0 for i, j in ((1, 0), (2, 0), (2, 1))):
            pr.append("compass: soft_iron is not upper triangular")
        ref = p.get("reference")
        names = {"north_nT", "east_nT", "down_nT", "total_nT", "inclination_deg", "declination_deg"}
        if not (isinstance(ref, dict) and set(ref) >= names):
            pr.append(f"compass: reference lacks {names - set(ref or {})}")
    elif procedure == "gyro-drift":
        if not _vec(p.get("drift")):
            pr.append("gyro-drift: drift [3] expected")
        if "mode" not in p:
            pr.append("gyro-drift: no mode")
        if p.get("mode") in ("B", "static"):
            for k in ("pitch_deg", "roll_deg", "earth_rate_body"):
                if k not in p:
                    pr.append(f"gyro-drift mode B: no {k}")
    elif procedure == "ldv":
        for b in ("beam1", "beam2", "beam3"):
            beam = p.get(b)
            if not (
                isinstance(beam, dict)
                and all(_num(beam.get(k)) for k in ("dK", "alpha_deg", "beta_deg", "gamma_deg", "sigma_mps"))
            ):
                pr.append(f"ldv: {b} lacks dK, alpha_deg, beta_deg, gamma_deg, sigma_mps")
        if not _num(p.get("condition_number")):
            pr.append("ldv: no condition_number")
    return pr


# -------------------------------------------------------------------------------- diagnose.md

CANONICAL = {
    "temperature_bias", "time_drift", "quadratic", "scale_asymmetry", "misalignment", "cubic", "lever_arm",
    "earth_rate", "g_sensitivity", "mag_accel_misalignment", "field_anomaly", "time_varying_hard_iron",
    "time_delay", "offset",
}  # fmt: skip
DRIVERS = {"time", "temperature", "input", "input_axis", "speed", "rate"}
SHAPES = {"linear", "step", "periodic", "smooth"}


def _fit_problems(f, where: str) -> list[str]:
    if not isinstance(f, dict):
        return [f"{where} is not an object"]
    pr = [f"{where}: no '{k}'" for k in ("model", "params", "residual_rms", "cv_rms") if k not in f]
    for k in ("residual_rms", "cv_rms"):
        if k in f and not (_num(f[k]) and f[k] >= 0):
            pr.append(f"{where}.{k} = {f[k]!r}")
    return pr


def check_diagnose(d: dict, procedure: str) -> list[str]:
    """The statements of diagnose.md that one `diagnose --json` object breaks."""
    pr: list[str] = []
    for key in ("procedure", "baseline", "candidates", "effects", "extended", "quality", "verdict"):
        if key not in d:
            pr.append(f"no '{key}'")
    if pr:
        return pr
    if d["procedure"] != procedure:
        pr.append(f"procedure {d['procedure']!r}, capture says {procedure!r}")
    pr += _fit_problems(d["baseline"], "baseline") + _fit_problems(d["extended"], "extended")
    for c in d["candidates"]:
        if not all(k in c for k in ("name", "delta_bic", "cv_rms", "selected")):
            pr.append(f"candidate {c.get('name')!r} lacks name/delta_bic/cv_rms/selected")
        elif not isinstance(c["selected"], bool):
            pr.append(f"candidate {c['name']}: selected is not true/false")
        elif c.get("resolvable", True) and not (_num(c["delta_bic"]) and _num(c["cv_rms"])):
            pr.append(f"candidate {c['name']}: resolvable but delta_bic/cv_rms not numbers")
    effects = d["effects"]
    names = set()
    for e in effects:
        missing = [
            k
            for k in ("name", "params", "uncertainty", "cv_rms_before", "cv_rms_after", "gain", "confused_with")
            if k not in e
        ]
        if missing:
            pr.append(f"effect {e.get('name')!r} lacks {missing}")
            continue
        names.add(e["name"])
        if _num(e["cv_rms_before"]) and _num(e["cv_rms_after"]) and e["cv_rms_before"] > 0 and _num(e["gain"]):
            if not math.isclose(e["gain"], 1 - e["cv_rms_after"] / e["cv_rms_before"], rel_tol=1e-6, abs_tol=1e-9):
                pr.append(f"effect {e['name']}: gain {e['gain']} is not 1 − cv_rms_after / cv_rms_before")
        else:
            pr.append(f"effect {e['name']}: cv_rms_before/after/gain not numbers")
        if not isinstance(e["confused_with"], list):
            pr.append(f"effect {e['name']}: confused_with is not a list")
        if e["name"].startswith("residual:"):
            if e["name"][9:] not in DRIVERS:
                pr.append(f"effect {e['name']}: driver not in the spec's list")
            if e.get("shape") not in SHAPES:
                pr.append(f"effect {e['name']}: shape {e.get('shape')!r}")
            if "correlation" not in e:
                pr.append(f"effect {e['name']}: no correlation with the canonical candidates")
    verdict = d["verdict"]
    if not isinstance(verdict, list):
        pr.append("verdict is not a list")
    else:
        if (verdict == []) != (effects == []):
            pr.append(f"verdict {verdict} against {len(effects)} effects")
        if not set(verdict) <= names | {
            c.get("name") for e in effects for c in e.get("confused_with", []) if isinstance(c, dict)
        }:
            pr.append(f"verdict {verdict} names what no effect holds")
    if not isinstance(d["quality"], list):
        pr.append("quality is not a list")
    else:
        for q in d["quality"]:
            if isinstance(q, dict) and q.get("kind") == "residuals_not_white":
                if not any("p" in k for k in q) or "drivers" not in q or "test" not in q:
                    pr.append("residuals_not_white lacks test, p-value or drivers")
    return pr


# ------------------------------------------------------------- calibrate.md's equations, on the data

_TO_SI = {"rad/s": 1.0, "deg/s": math.pi / 180, "m/s^2": 1.0, "g": 9.80665}


def check_calibrate_equations(d: dict, raw: bytes) -> list[str]:
    """The `convention` column of calibrate.md applied to the capture's own rows: the parameters,
    read in the units the spec gives them, must map the raw data as the equation says."""
    meta, cols = columns(raw)
    p = d["params"]
    pr: list[str] = []

    def mean(xs):
        xs = [x for x in xs if not math.isnan(x)]
        return sum(xs) / len(xs)

    def rows(*names):
        return [r for r in zip(*(cols[n] for n in names)) if not any(math.isnan(x) for x in r)]

    proc = meta.get("procedure")
    if proc == "accel-tabletop":  # A = B + M V, A in m/s²: |A| is local gravity on every still row
        B, M = p["B"], p["M"]
        norms = [
            math.hypot(*(B[i] + sum(M[i][j] * v[j] for j in range(3)) for i in range(3)))
            for v in rows("ax", "ay", "az")
        ]
        g = float(meta.get("g_mps2", 9.80))
        norms.sort()
        median = norms[len(norms) // 2]
        if not abs(median - g) < 0.02 * g:
            pr.append(f"accel-tabletop: median |B + M V| {median:.4f} m/s^2, not g {g}")
    elif proc == "compass":  # m = W (m_raw − h) in nT, |m| matching the reference's total field
        ref = p["reference"]
        if _num(ref.get("total_nT")):
            W, h = p["soft_iron"], p["hard_iron"]
            mags = []
            for v in rows("mx", "my", "mz"):
                x = [v[j] - h[j] for j in range(3)]
                mags.append(math.hypot(*(sum(W[i][j] * x[j] for j in range(3)) for i in range(3))))
            mags.sort()
            median = mags[len(mags) // 2]
            if not abs(median - ref["total_nT"]) < 0.02 * ref["total_nT"]:
                pr.append(f"compass: median |W (m_raw − h)| {median:.1f}, reference total_nT {ref['total_nT']:.1f}")
            if not math.isclose(
                math.hypot(ref["north_nT"], ref["east_nT"], ref["down_nT"]), ref["total_nT"], rel_tol=1e-6
            ):
                pr.append("compass: total_nT is not the norm of north, east, down")
            incl = math.degrees(math.atan2(ref["down_nT"], math.hypot(ref["north_nT"], ref["east_nT"])))
            decl = math.degrees(math.atan2(ref["east_nT"], ref["north_nT"]))
            if abs(incl - ref["inclination_deg"]) > 1e-6 or abs(decl - ref["declination_deg"]) > 1e-6:
                pr.append("compass: inclination_deg/declination_deg disagree with north, east, down")
    elif proc == "gyro-drift" and meta.get("gyro_unit") in _TO_SI and p.get("mode") == "static":
        # ω' = ω − ε, drift in rad/s: the record's mean rate less the Earth rate (body axes; the simulator's
        # device axes are the body axes, frame key) — or the plain mean with a warning when it is unknown
        scale = _TO_SI[meta["gyro_unit"]]
        w = [mean(cols[k]) * scale for k in ("gx", "gy", "gz")]
        e = p["earth_rate_body"] if p.get("earth_rate_body") is not None else [0.0, 0.0, 0.0]
        if p.get("earth_rate_body") is None and not any("latitude" in x or "Earth" in x for x in d["warnings"]):
            pr.append("gyro-drift: Earth rate not removed and no warning says so")
        if meta.get("frame", "").startswith("body x forward, y up, z right"):
            for i in range(3):
                if abs(p["drift"][i] - (w[i] - e[i])) > 1e-6 + 1e-3 * abs(w[i]):
                    pr.append(f"gyro-drift: drift[{i}] {p['drift'][i]!r} rad/s, mean − Earth rate {w[i] - e[i]!r}")
    elif proc == "ldv" and {"vx", "vy", "vz"} <= set(cols):
        # V_L = (1 + δK)(V_x cos α + V_y cos β + V_z cos γ); the residual's scatter is sigma_mps
        for k in (1, 2, 3):
            b = p[f"beam{k}"]
            c = [math.cos(math.radians(b[a])) for a in ("alpha_deg", "beta_deg", "gamma_deg")]
            if not math.isclose(sum(x * x for x in c), 1.0, abs_tol=1e-6):
                pr.append(f"ldv: beam{k}'s angles are not the direction angles of one unit vector")
            res = [
                r[0] - (1 + b["dK"]) * (c[0] * r[1] + c[1] * r[2] + c[2] * r[3])
                for r in rows(f"vl{k}", "vx", "vy", "vz")
            ]
            rms = math.sqrt(sum(x * x for x in res) / len(res))
            if not rms < 1.5 * b["sigma_mps"] + 1e-9:
                pr.append(f"ldv: beam{k} residual rms {rms:.4g} m/s against sigma_mps {b['sigma_mps']:.4g}")
    return pr
