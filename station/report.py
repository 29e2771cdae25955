"""The calibration report: one self-contained HTML page a lab can file and sign.

``build_report(store, calibration_id) -> dict`` gathers what the page states (from the
database only: the calibration, its capture, the device, the calibration it was compared
with, the device's drift history, the `station verify` status); ``render_html(report)``
writes the page: inline CSS and inline SVG figures (``station.svgplot``), no external
assets, no scripts, print-ready (A4, the browser's "Print to PDF" gives the PDF).

Expanded uncertainty: U = k·u with coverage factor k = 2 (about 95 % for a normal
distribution, JCGM 100:2008 (GUM) §6), u the standard uncertainty the fit reports (1σ).
"""

from __future__ import annotations

import math
from datetime import UTC, datetime
from html import escape

import numpy as np

from station import __version__
from station.formatting import num, sigma
from station.procedures import registry
from station.procedures.review import (
    assess,
    display_unit,
    flatten,
    param_unit,
    record_result,
    residual_of,
    result_unit,
    shown_residual,
    shown_rows,
    shown_unit,
    shown_value,
)

K_COVERAGE = 2.0

# capture metadata keys the report states (entered on Connect, or in the capture file)
META_OPERATOR = ("operator",)
META_PLACE = ("place", "site", "location")
META_REFERENCE = ("reference_equipment", "reference")


def _first(meta: dict, keys) -> str | None:
    for k in keys:
        v = meta.get(k)
        if v not in (None, ""):
            return str(v)
    return None


def _posix(iso: str) -> float:
    text = iso[:-1] + "+00:00" if iso.endswith("Z") else iso
    dt = datetime.fromisoformat(text)
    if dt.tzinfo is None:
        dt = dt.replace(tzinfo=UTC)
    return dt.timestamp()


def _previous_of(store, cal: dict) -> dict | None:
    """The calibration this one was compared with: the one its review names, else the
    device's last accepted calibration of the procedure before it."""
    review = cal.get("review") or {}
    if review.get("previous_calibration_id"):
        try:
            return store.calibration(review["previous_calibration_id"])
        except LookupError:
            pass
    earlier = [
        h
        for h in store.history(cal["device_id"], cal["procedure"])
        if h["accepted"] and (h["time"], h["id"]) < (cal["time"], cal["id"])
    ]
    return store.calibration(earlier[-1]["id"]) if earlier else None


def build_report(store, calibration_id: int) -> dict:
    """Everything the page states, as plain data (raises db.store.NotFound)."""
    cal = store.calibration(calibration_id)
    device = store.get_device(cal["device_id"]) or {"id": cal["device_id"]}
    capture_info, meta, columns = None, {}, {}
    if cal["capture_id"] is not None:
        capture_info = store.capture_info(cal["capture_id"])
        meta, columns = store.load_capture(cal["capture_id"])
    previous = _previous_of(store, cal)
    back_dated = store.back_dated_before(calibration_id)  # saved after it, dated before it
    result = cal["result"]
    assessment = assess(result, previous, device)
    history = [h for h in store.history(cal["device_id"], cal["procedure"]) if h["accepted"] or h["id"] == cal["id"]]
    problems = store.verify()
    mine = [
        p
        for p in problems
        if p.get("calibration_id") == cal["id"]
        or (cal["capture_id"] is not None and p.get("capture_id") == cal["capture_id"])
        or p.get("device_id") == cal["device_id"]
    ]
    temp = columns.get("temp_c")
    conditions = {}
    if temp is not None and len(temp) and np.isfinite(temp).any():
        t = np.asarray(temp, dtype=float)
        t = t[np.isfinite(t)]
        conditions["temperature_c"] = (float(t.mean()), float(t.min()), float(t.max()))
    for key in ("temperature_c", "humidity_pct", "pressure_hpa"):
        if meta.get(key) not in (None, "") and key not in conditions:
            conditions[key] = meta[key]
    return {
        "calibration": cal,
        "device": device,
        "capture": capture_info,
        "meta": meta,
        "columns": columns,
        "previous": previous,
        "back_dated": back_dated,
        "assessment": assessment,
        "history": history,
        "verify_problems": mine,
        "verify_other": len(problems) - len(mine),
        "conditions": conditions,
        "generated": datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
    }


# ------------------------------------------------------------------------- rendering


def _row(label: str, value) -> str:
    return f"<tr><th>{escape(label)}</th><td>{value}</td></tr>"


def _e(x) -> str:
    return escape("—" if x in (None, "") else str(x))


def _figures(rep: dict) -> list[tuple[str, str]]:
    """(caption, svg) for each figure this calibration has data for."""
    from station import svgplot

    cal, result, meta, columns = rep["calibration"], rep["calibration"]["result"], rep["meta"], rep["columns"]
    proc = cal["procedure"]
    figs = []
    entry = registry.get(proc)
    own = getattr(entry.load(), "report_figures", None) if entry is not None else None
    if own is not None:  # the procedure's own figures (its module's report_figures)
        figs += own(result, meta, columns)
    allan = result.get("allan")
    if isinstance(allan, dict) and allan.get("tau_s") and allan.get("adev_rad_s"):
        tau = allan["tau_s"]
        series = [
            {
                "x": tau,
                "y": [v * 180 / math.pi * 3600 if v is not None else None for v in adev],
                "label": f"{axis} axis",
                "mode": "both",
            }
            for axis, adev in zip("xyz", allan["adev_rad_s"])
        ]
        figs.append(
            (
                "Allan deviation of the gyro rate per axis (overlapping), °/h against averaging time τ",
                svgplot.xy_plot(
                    series, x_label="τ  [s]", y_label="σ(τ)  [°/h]", log_x=True, log_y=True, title="Allan deviation"
                ),
            )
        )
    hist = [h for h in rep["history"] if h["accepted"] or h["id"] == cal["id"]]
    if len(hist) >= 2:
        blocks: dict[str, list[str]] = {}
        first = flatten(hist[0]["params"])
        for name in first:
            blocks.setdefault(name.split("[", 1)[0], []).append(name)
        times = [_posix(h["time"]) for h in hist]
        for block, names in list(blocks.items())[:4]:
            series = []
            for name in names[:6]:  # in the units the screens show (each calibration's own factor)
                vals = [_shown(h, name, flatten(h["params"]).get(name)) for h in hist]
                sig = [_shown(h, name, flatten(h["uncertainty"]).get(name)) for h in hist]
                v0 = vals[0]
                if v0 is None:
                    continue
                series.append(
                    {
                        "x": times,
                        "y": [None if v is None else v - v0 for v in vals],
                        "err": sig,
                        "label": name,
                        "mode": "both",
                    }
                )
            if not series:
                continue
            unit = shown_unit(result, names[0])
            figs.append(
                (
                    f"Drift history of {block}: change since the first accepted calibration "
                    f"({hist[0]['time'][:10]}), ±1σ bars, {unit or 'units of the parameter'}",
                    svgplot.xy_plot(
                        series,
                        x_label="calibration date (UTC)",
                        y_label=f"Δ{block}  [{unit or '1'}]",
                        time_x=True,
                        hline=0.0,
                        title=f"drift of {block}",
                    ),
                )
            )
    return figs


def _shown(record: dict, name: str, x):
    return None if x is None else shown_value(record_result(record), name, x)


def _stored_units_note(result: dict, rows) -> str:
    """Which parameters the page shows in another unit than the stored result's (its JSON,
    exports and database), e.g. P4's drift: '' when none."""
    said = {}
    for r in rows:
        block = r.name.split("[", 1)[0]
        if block not in said and display_unit(result, r.name) is not None:
            said[block] = f"{block} in {param_unit(result, r.name) or 'its stored unit'}"
    if display_unit(result, "residual_rms") is not None:
        said["residual_rms"] = f"the residual in {result_unit(result)}"
    return ", ".join(said.values())


CSS = """
body { font-family: sans-serif; font-size: 13px; color: #111; margin: 24px auto; max-width: 900px; }
h1 { font-size: 20px; margin: 0 0 4px; } h2 { font-size: 15px; margin: 20px 0 6px; border-bottom: 1px solid #999; }
table { border-collapse: collapse; width: 100%; } th, td { padding: 2px 6px; text-align: left; vertical-align: top; }
table.kv th { width: 28%; color: #333; font-weight: normal; } table.params td, table.params th { border-bottom: 1px solid #ddd; }
table.params td.num { text-align: right; font-variant-numeric: tabular-nums; }
.pass { color: #fff; background: #2a7d2a; padding: 1px 6px; } .fail { color: #fff; background: #b00020; padding: 1px 6px; }
.none { background: #ddd; padding: 1px 6px; } .bad { color: #b00020; } .ok { color: #2a7d2a; }
figure { margin: 10px 0; page-break-inside: avoid; } figcaption { color: #333; margin-top: 2px; }
.sign td { height: 40px; border-bottom: 1px solid #333; } code { font-size: 12px; word-break: break-all; }
@page { size: A4; margin: 15mm; } @media print { body { margin: 0; max-width: none; } }
"""


def render_html(rep: dict) -> str:
    cal, dev, meta = rep["calibration"], rep["device"], rep["meta"]
    result = cal["result"]
    a = rep["assessment"]
    proc = cal["procedure"]
    entry = registry.get(proc)
    short, what, source = (entry.code, entry.description, entry.source) if entry is not None else (proc, proc, "—")
    review = cal.get("review") or {}
    decision = review.get("decision") or ("accepted" if cal["accepted"] else "rejected")
    word = review.get("verdict") or a.verdict
    cls = {"pass": "pass", "fail": "fail"}.get(word, "none")
    prev = rep["previous"]
    place = _first(meta, META_PLACE)
    lat, lon = meta.get("latitude_deg"), meta.get("longitude_deg")
    if lat not in (None, "") and lon not in (None, ""):
        place = (
            (place + "; " if place else "")
            + f"{lat}° N, {lon}° E"
            + (f", {meta['altitude_m']} m" if meta.get("altitude_m") not in (None, "") else "")
        )
    cond = rep["conditions"]
    temp = cond.get("temperature_c")
    if isinstance(temp, tuple):
        temp_text = f"{temp[0]:.1f} °C (from {temp[1]:.1f} to {temp[2]:.1f} °C during the capture)"
    else:
        temp_text = f"{temp} °C" if temp else "not recorded"
    problems = rep["verify_problems"]
    if problems:
        verify = (
            "<span class='bad'>CHANGED after it was written: "
            + "; ".join(escape(f"{p['kind']}: {p.get('detail', '')}") for p in problems)
            + "</span>"
        )
    else:
        verify = (
            "<span class='ok'>ok</span>: this calibration, its capture and the device's chain are unchanged "
            "since they were written"
        )
    title = f"Calibration report #{cal['id']}: {dev.get('id')} ({short})"
    h = [
        f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>{escape(title)}</title>"
        f"<style>{CSS}</style></head><body>",
        f"<h1>{escape(title)}</h1>",
        f"<p>Result: <span class='{cls}' id='verdict'>{escape(word.upper())}</span> · decision: "
        f"<b id='decision'>{escape(decision)}</b>"
        + (f" · note: {escape(review['note'])}" if review.get("note") else "")
        + "</p>",
        "<h2>Device and procedure</h2><table class='kv'>",
        _row("Device", _e(dev.get("id")) + (f" (model {_e(dev.get('model'))})" if dev.get("model") else "")),
        _row("Procedure", f"{escape(short)} <code>{escape(proc)}</code>: {escape(what)}"),
        _row("Source document", escape(source)),
        _row("Model", _e(result.get("model"))),
        _row("Method", _e(result.get("method"))),
        "</table><h2>Who, where, when</h2><table class='kv'>",
        _row("Operator", _e(cal.get("operator") or _first(meta, META_OPERATOR))),
        _row("Station (host)", _e(cal.get("host"))),
        _row("Place", _e(place)),
        _row("Date and time (UTC)", _e(cal["time"].replace("T", " ").replace("Z", " UTC"))),
        _row("Saved", _e(cal.get("saved_at"))),
        _row("Conditions: temperature", escape(temp_text)),
    ]
    for key, label in (("humidity_pct", "Conditions: humidity"), ("pressure_hpa", "Conditions: pressure")):
        if key in cond:
            h.append(_row(label, _e(cond[key])))
    h += [
        _row("Reference equipment", _e(_first(meta, META_REFERENCE))),
        _row("Software", _e(f"station {cal.get('software_version') or '—'} (report by {__version__})")),
        "</table>",
    ]
    # parameters
    h.append(
        "<h2>Parameters</h2><p>u: standard uncertainty (1σ, from the fit's covariance); U = k·u, "
        f"expanded uncertainty with coverage factor k = {K_COVERAGE:g} (about 95 %). "
        "Tolerance: the largest change from the calibration in use; limits: absolute."
        + (
            f" Shown in the units of the station's screens; the stored result and its exports keep {escape(note)}."
            if (note := _stored_units_note(result, a.rows))
            else ""
        )
        + "</p>"
    )
    h.append(
        "<table class='params' id='params'><tr><th>parameter</th><th>value</th><th>u (k=1)</th>"
        "<th>U (k=2)</th><th>unit</th><th>previous</th><th>change</th><th>tolerance / limits</th>"
        "<th>check</th></tr>"
    )
    for r in shown_rows(result, a.rows):  # in the units the screens show (the checks were made as stored)
        U = K_COVERAGE * r.sigma if isinstance(r.sigma, (int, float)) and r.sigma is not None else None
        change = (r.value - r.previous) if (r.previous is not None and r.value is not None) else None
        lim = []
        if r.tolerance is not None:
            lim.append(f"±{r.tolerance:g}")
        if r.limit is not None:
            lo, hi = r.limit
            lim.append(f"[{'−∞' if lo is None else format(lo, 'g')}, {'∞' if hi is None else format(hi, 'g')}]")
        ok = {True: "<span class='ok'>pass</span>", False: "<span class='bad'>FAIL</span>", None: "—"}[r.ok]
        h.append(
            f"<tr><td><code>{escape(r.name)}</code></td><td class='num'>{num(r.value, '.7g')}</td>"
            f"<td class='num'>{sigma(r.sigma)}</td><td class='num'>{sigma(U)}</td>"
            f"<td>{escape(r.unit)}</td><td class='num'>{num(r.previous, '.7g')}</td>"
            f"<td class='num'>{num(change, '+.3g')}</td><td>{escape(' '.join(lim)) or '—'}</td><td>{ok}</td></tr>"
        )
    h.append("</table>")
    res, res_unit = shown_residual(result)
    of = residual_of(result)  # what the RMS is over, as calibrate says it (P4: per sample)
    h.append(
        f"<p>Residual RMS {num(res, '.4g')} {escape(res_unit)}{escape(' ' + of) if of else ''} · "
        f"{_e(registry.count_text(result.get('procedure'), result.get('n_positions')))}.</p>"
    )
    if review.get("reasons") or a.reasons:
        h.append(
            "<p><b>Why it failed:</b></p><ul>"
            + "".join(f"<li>{escape(x)}</li>" for x in (review.get("reasons") or a.reasons))
            + "</ul>"
        )
    if result.get("warnings"):
        h.append(
            "<p><b>Warnings:</b></p><ul>" + "".join(f"<li>{escape(str(w))}</li>" for w in result["warnings"]) + "</ul>"
        )
    # previous and drift
    h.append("<h2>Previous calibration and drift</h2>")
    if prev:
        h.append(
            f"<p>Compared with calibration #{prev['id']} of {escape(prev['time'])} "
            f"({'accepted' if prev['accepted'] else 'rejected'}), the calibration in use before this one.</p>"
        )
    else:
        h.append("<p>No earlier accepted calibration of this procedure: nothing to compare with.</p>")
    if rep.get("back_dated"):  # a capture dated before this one, saved after it (station.store)
        from station.store import back_dated_line

        h.append(f"<p id='back-dated'>Back-dated since: {escape(back_dated_line(cal, rep['back_dated']))}.</p>")
    n_acc = sum(1 for x in rep["history"] if x["accepted"])
    h.append(f"<p>{n_acc} accepted calibration{'s' if n_acc != 1 else ''} of this procedure in the history.</p>")
    # figures
    figs = _figures(rep)
    h.append("<h2>Figures</h2>" if figs else "<h2>Figures</h2><p>No figure for this calibration's data.</p>")
    for i, (caption, svg) in enumerate(figs, 1):
        h.append(f"<figure id='fig{i}'>{svg}<figcaption>Figure {i}. {escape(caption)}</figcaption></figure>")
    # integrity
    cap = rep["capture"]
    h.append("<h2>Record and integrity</h2><table class='kv'>")
    h.append(_row("Calibration record hash (sha256)", f"<code>{_e(cal.get('hash'))}</code>"))
    h.append(
        _row(
            "Capture",
            f"#{cap['id']}, {cap['n_rows']} rows, columns {escape(', '.join(cap['column_names']))}" if cap else "—",
        )
    )
    h.append(_row("Capture hash (sha256)", f"<code>{_e(cal.get('capture_sha256'))}</code>"))
    h.append(_row("station verify", verify))
    h.append("</table>")
    h.append(
        "<h2>Approval</h2><table class='kv sign'><tr><th>Calibrated by</th><td></td></tr>"
        "<tr><th>Checked and approved by</th><td></td></tr><tr><th>Date</th><td></td></tr></table>"
    )
    h.append(
        f"<p style='color:#666'>Generated {escape(rep['generated'])} by <code>station report {cal['id']}</code>."
        "</p></body></html>"
    )
    return "\n".join(h)
