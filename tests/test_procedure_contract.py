"""Every procedure of the registry has the declared shape, and the registry is the one list.

- each module satisfies ``contract.ProcedureModule`` and its files follow its stem
  (module, guide and screen when guided, doc, test);
- simulate → calibrate → diagnose runs through each module: the diagnosis of a capture
  with a strong time drift names it (sizes ~20σ of what the capture resolves, from
  ``benchmarks/bench_diagnose.py``), and a capture is prepared once for both;
- the CLI's choices, the capture reader and ``solvers.simulate`` agree with the registry;
- a sixth procedure is one registry entry plus one module (a toy, written here).
"""

from __future__ import annotations

import inspect
import json
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from solvers import simulate as S
from station.capture import Capture, read_capture
from station.procedures import registry
from station.procedures.contract import DiagnosisInput, ProcedureModule

ROOT = Path(__file__).resolve().parents[1]
ENTRIES = registry.PROCEDURES
IDS = [p.name for p in ENTRIES]

# time_drift sizes (units of solvers.models.*.effect_blocks) of about 20σ of what one
# default simulated capture resolves (bench_diagnose.py's detection table, 1σ column)
STRONG_TIME_DRIFT = {"accel-tabletop": 0.1, "accel-centrifuge": 2e-4, "compass": 20.0, "gyro-drift": 0.02, "ldv": 0.05}
# the benchmark's design for P1: 12 extra positions leave the norm fit degrees of freedom
# (with the 12 default positions a drift in time is not told apart from the quadratic term)
OPTIONS = {"accel-tabletop": {"extra_positions": 12}}


@pytest.mark.parametrize("entry", ENTRIES, ids=IDS)
def test_module_satisfies_the_protocol(entry):
    module = entry.load()
    assert isinstance(module, ProcedureModule), f"{entry.module} lacks part of the contract"
    assert "prepared" in inspect.signature(module.calibrate).parameters
    assert list(inspect.signature(module.diagnosis_input).parameters)[:3] == ["capture", "base", "prepared"]
    assert isinstance(module.DIAGNOSIS_BASELINE, bool)


@pytest.mark.parametrize("entry", ENTRIES, ids=IDS)
def test_each_stem_has_its_files(entry):
    assert entry.module == f"station.procedures.{entry.stem}"
    assert (ROOT / "station" / "procedures" / f"{entry.stem}.py").is_file()
    assert (ROOT / "tests" / f"test_{entry.stem}.py").is_file()
    assert (ROOT / "docs" / f"{entry.doc}.md").is_file()
    assert entry.code in (ROOT / "docs" / f"{entry.doc}.md").read_text(encoding="utf-8")
    if entry.screen:
        module, cls = entry.screen.split(":")
        assert module == f"station.screens.{entry.stem}"
        assert f"class {cls}(" in (ROOT / "station" / "screens" / f"{entry.stem}.py").read_text(encoding="utf-8")
        assert (ROOT / "station" / "procedures" / f"{entry.stem}_guide.py").is_file()
        assert (ROOT / "tests" / f"test_{entry.stem}_guide.py").is_file()


def test_registry_codes_and_names_are_unique():
    assert len(set(IDS)) == len(IDS) and len({p.code for p in ENTRIES}) == len(ENTRIES)
    assert [p.code for p in ENTRIES] == [f"P{k + 1}" for k in range(len(ENTRIES))]


def test_solvers_keep_the_same_list():
    """solvers/ never imports the station: its own list is held equal here."""
    assert tuple(S.PROCEDURES) == registry.names()
    assert set(S.EFFECTS_BY_PROCEDURE) == set(registry.names())


@pytest.mark.parametrize("entry", ENTRIES, ids=IDS)
def test_the_registry_says_which_simulators_take_a_site(entry):
    """`station simulate` passes --date as the site's date where the registry says the
    simulator takes one (it read the simulator's signature): the two agree."""
    takes = "site" in inspect.signature(getattr(S, entry.simulator)).parameters
    assert entry.takes_site == takes, entry.name


def test_cli_choices_are_the_registry():
    from station.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    seen = 0
    for name in ("simulate", "record", "sim-device", "walkthrough", "history", "drift"):
        opt = next(a for a in sub.choices[name]._actions if "--procedure" in a.option_strings)
        # sim-device also simulates the benches of the guided runs with a reference IMU (P4 mode A)
        extra = tuple(r.name for r in registry.GUIDED_RUNS if r.reference) if name == "sim-device" else ()
        assert tuple(opt.choices) == registry.names() + extra, name
        seen += 1
    assert seen == 6


@pytest.mark.parametrize("entry", ENTRIES, ids=IDS)
def test_simulate_calibrate_diagnose_round_trip(entry, monkeypatch):
    from station.calibrate import calibrate_capture
    from station.procedures.diagnose import analyse

    module = entry.load()
    sim = S.simulate(
        entry.name, seed=11, effects={"time_drift": STRONG_TIME_DRIFT[entry.name]}, **OPTIONS.get(entry.name, {})
    )
    cap = Capture(meta=dict(sim.meta), columns=dict(sim.columns), path=f"sim-{entry.stem}.csv")
    result = calibrate_capture(cap)
    assert result["procedure"] == entry.name and np.isfinite(result["residual_rms"])
    assert module.format_text(result).strip()
    # every parameter the result holds is one PARAM_SHAPES declares (limits and tolerances of a
    # device with no calibration yet are checked against those names)
    from station.commands.devices import _every_procedures_names
    from station.procedures.review import block_of, flatten

    declared = _every_procedures_names()
    assert all(k in declared.get(block_of(k), ()) for k in flatten(result["params"])), flatten(result["params"])

    calls = []
    real = module.prepare
    monkeypatch.setattr(module, "prepare", lambda c, *a, **k: calls.append(1) or real(c, *a, **k))
    out, diag, inp = analyse(cap)
    assert len(calls) == 1, "analyse prepared the capture more than once"
    assert isinstance(inp, DiagnosisInput) and inp.problem is diag.problem
    assert out["procedure"] == entry.name
    assert "time_drift" in out["verdict"], out["verdict"]


TOY = '''
"""A toy sixth procedure: a thermometer's offset against a reference (tests only)."""
import numpy as np

from solvers.diagnose.engine import Candidate, Problem
from station.procedures.contract import DiagnosisInput

MODEL = "T = T_ref + c"
DIAGNOSIS_BASELINE = True
MEASURED = ("temp_c", "ref_temp_c")
CORE_PARAMS = ("c",)
PARAM_UNITS = {"c": "°C"}


def prepare(capture):
    d = np.asarray(capture.column("temp_c"), float) - np.asarray(capture.column("ref_temp_c"), float)
    return {"d": d, "t": np.asarray(capture.column("t"), float), "warnings": []}


def calibrate(capture, method=None, *, prepared=None):
    p = prepared if prepared is not None else prepare(capture)
    c, n = float(np.mean(p["d"])), len(p["d"])
    s = float(np.std(p["d"], ddof=1))
    return {"procedure": "thermo-offset", "device": capture.meta.get("device"), "model": MODEL,
            "params": {"c": c}, "uncertainty": {"c": s / np.sqrt(n)}, "residual_rms": s,
            "n_positions": n, "warnings": list(p["warnings"])}


def format_text(result):
    return f"procedure  thermo-offset\\nc          {result['params']['c']:.4f} °C"


def diagnosis_input(capture, base, prepared=None):
    p = prepared if prepared is not None else prepare(capture)
    d, t = p["d"], p["t"]

    def residual(q):
        return q["c"][0] + q.get("bt", np.zeros(1))[0] * (t - t.mean()) - d

    prob = Problem("thermo-offset", MODEL, residual, np.full(len(d), base["residual_rms"]),
                   np.arange(len(d)) // 50, {"c": np.array([base["params"]["c"]])}, {"c": True},
                   [Candidate("time_drift", {"bt": np.zeros(1)})], 1.0, unit="°C")
    return DiagnosisInput(prob, {}, "a reading far off the others")
'''


def test_a_sixth_procedure_is_one_entry_and_one_module(tmp_path, monkeypatch, capsys):
    """The toy is added to the registry and its module written to a folder on sys.path;
    nothing else changes: the capture reader accepts it, `station calibrate` and
    `station diagnose` run it, `station simulate` offers it."""
    from station.cli import build_parser, main

    (tmp_path / "toy_thermo.py").write_text(textwrap.dedent(TOY), encoding="utf-8")
    monkeypatch.syspath_prepend(str(tmp_path))
    toy = registry.Procedure(
        name="thermo-offset",
        code="P6",
        stem="toy_thermo",
        title="thermometer offset",
        short="thermometer",
        sensor_kind="temp",
        module="toy_thermo",
        screen=None,
        result_unit="°C",
        doc="toy",
        description="thermometer against a reference thermometer, one offset",
        source="toy document T-6",
        units_note="temperatures in degrees Celsius",
    )
    monkeypatch.setattr(registry, "PROCEDURES", registry.PROCEDURES + (toy,))
    rng = np.random.default_rng(6)
    t = np.arange(400) * 0.5
    ref = 20.0 + 0.01 * t
    temp = ref + 0.3 + 0.002 * (t - t.mean()) + rng.normal(0, 0.01, t.size)  # offset and a drift
    path = tmp_path / "toy.csv"
    lines = ["# station-capture: 1", "# procedure: thermo-offset", "# device: TH-1", "t,temp_c,ref_temp_c"]
    lines += [f"{a:.3f},{b:.5f},{c:.5f}" for a, b, c in zip(t, temp, ref)]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")

    assert read_capture(path).procedure == "thermo-offset"
    assert main(["calibrate", str(path), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["params"]["c"] == pytest.approx(0.3, abs=0.01)
    assert main(["diagnose", str(path), "--json", "--no-plots"]) == 0
    assert json.loads(capsys.readouterr().out)["verdict"] == ["time_drift"]
    sub = next(a for a in build_parser()._actions if a.__class__.__name__ == "_SubParsersAction")
    opt = next(a for a in sub.choices["simulate"]._actions if "--procedure" in a.option_strings)
    assert "thermo-offset" in opt.choices
    assert "toy_thermo" in sys.modules

    # the per-procedure facts the rest of the station reads come from the entry and the module
    db = tmp_path / "station.db"
    assert main(["devices", "add", "TH-1", "--kind", "temp", "--db", str(db)]) == 0  # its sensor kind
    assert main(["calibrate", str(path), "--save", "--db", str(db)]) == 0
    capsys.readouterr()
    assert main(["export", "1", "--format", "c-header", "--db", str(db)]) == 0
    assert "/* units: temperatures in degrees Celsius */" in capsys.readouterr().out  # units_note
    assert main(["export", "1", "--format", "px4", "--db", str(db)]) == 2  # no firmware parameters
    assert "procedure 'thermo-offset' has no parameters in PX4" in capsys.readouterr().err
    page = tmp_path / "report.html"
    assert main(["report", "1", "--out", str(page), "--db", str(db)]) == 0
    html = page.read_text(encoding="utf-8")
    assert "thermometer against a reference thermometer, one offset" in html and "toy document T-6" in html

    from station.procedures.review import param_unit

    assert param_unit(result, "c") == "°C"  # the module's PARAM_UNITS
    empty = tmp_path / "empty.csv"
    empty.write_text("\n".join(lines[:4] + [f"{a:.3f},,{c:.5f}" for a, c in zip(t, ref)]) + "\n", encoding="utf-8")
    assert main(["calibrate", str(empty)]) == 2  # the module's MEASURED: an all-empty column
    assert "column 'temp_c' is empty in every row" in capsys.readouterr().err


def test_no_table_keyed_by_a_procedure_outside_the_registry():
    """A string equal to a procedure's name or code (P1…P5), docstrings aside, stands only in
    the registry and in that procedure's own files (module, guide, screen): no table or
    switch elsewhere is keyed by a procedure."""
    import ast

    by_word = {p.name: p for p in ENTRIES} | {p.code: p for p in ENTRIES}
    found = set()
    for path in sorted(p for d in ("station", "db") for p in (ROOT / d).rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        tree = ast.parse(path.read_text(encoding="utf-8"))
        docs = {
            id(n.body[0].value)
            for n in ast.walk(tree)
            if isinstance(n, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
            and n.body
            and isinstance(n.body[0], ast.Expr)
            and isinstance(n.body[0].value, ast.Constant)
        }
        for node in ast.walk(tree):
            if not (isinstance(node, ast.Constant) and isinstance(node.value, str)) or id(node) in docs:
                continue
            entry = by_word.get(node.value)
            if entry is None or rel == "station/procedures/registry.py":
                continue
            own = {f"station/procedures/{entry.stem}.py", f"station/procedures/{entry.stem}_guide.py"}
            if rel in own | {f"station/screens/{entry.stem}.py"}:
                continue
            found.add((rel, node.value, node.lineno))
    assert not found, "\n".join(f"{f}:{n}: {w!r}" for f, w, n in sorted(found))


def test_the_lists_the_cli_offers_are_the_registry():
    """demo, import and devices offer what the registry says (built when the parser is)."""
    from station.cli import build_parser

    sub = next(a for a in build_parser()._actions if a.__class__.__name__ == "_SubParsersAction")

    def choices(command, option, parser=None):
        parser = parser or sub.choices[command]
        return tuple(next(a for a in parser._actions if option in a.option_strings).choices)

    assert choices("demo", "--procedure") == registry.demos()
    assert set(registry.demos()) == {p.name for p in ENTRIES if p.screen} | {"gyro-reference"}
    assert choices("import", "--procedure") == registry.importable() == ("accel-tabletop", "compass", "gyro-drift")
    devices = sub.choices["devices"]
    add = next(a for a in devices._actions if a.__class__.__name__ == "_SubParsersAction").choices["add"]
    assert choices(None, "--kind", add) == registry.sensor_kinds() == ("accel", "mag", "gyro", "ldv")


@pytest.mark.parametrize("name", list(registry.guided()))
def test_the_simulated_device_is_the_guides_and_says_the_registrys_id(name):
    """Every guided run's simulated device comes from its procedure's guide module and
    reports the id the Connect screen shows before starting it (registry ``sim_device``)."""
    from station.sources import SimSource

    src = SimSource(seed=7, procedure=name, clock=lambda: 0.0)
    assert src.device_id == SimSource.device_id_for(7, name)
    entry, reference = registry.device_of(name)
    assert entry.guide().__name__ == f"station.procedures.{entry.stem}_guide"
    assert bool(getattr(src.imu, "reference", False)) == reference
