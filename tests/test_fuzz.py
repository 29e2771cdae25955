"""The fuzz and extreme-value harness, a bounded fast share (the long run is
`benchmarks/bench_fuzz.py`, figures in docs/benchmarks.md): mutated and valid-but-extreme
captures of all five procedures through `calibrate` and `diagnose`, each in a worker with a
time limit. Nothing may hang, reach the last-resort error, write stray stdout or crash."""

from __future__ import annotations

import random

import pytest

from tests import fuzzkit as F

# A generous limit per run: a loaded 2-core machine is slow; a hang is "never returns".
TIMEOUT_S = 120.0


@pytest.fixture(scope="module")
def bases(tmp_path_factory):
    return F.make_bases(str(tmp_path_factory.mktemp("fuzz")), seed=5)


def _report(outcomes) -> str:
    return "\n".join(f"{o.kind} {o.command} {o.case}: {o.detail}" for o in outcomes if o.kind in F.FAILURES)


def test_bases_calibrate_and_diagnose_cleanly(bases, tmp_path):
    """The unmutated bases are valid captures the station calibrates and diagnoses (so the
    mutations below start from working input, not from something refused anyway)."""
    runner = F.Runner(timeout_s=TIMEOUT_S)
    try:
        outcomes = [runner.run(cmd, path, name) for name, path in sorted(bases.items()) for cmd in F.COMMANDS]
    finally:
        runner.close()
    assert [(o.case, o.command, o.kind) for o in outcomes if o.kind != "ok"] == [], _report(outcomes)


def test_mutated_and_extreme_captures_never_hang_crash_or_leak(bases, tmp_path):
    outcomes = F.run_campaign(str(tmp_path), bases, n_mutated=24, n_extreme=16, seed=2016, timeout_s=TIMEOUT_S)
    s = F.summary(outcomes)
    assert s["failures"] == [], _report(outcomes)
    assert s["mutated"] == 24 and s["extreme"] >= 12
    assert s["counts"].get("refused", 0) > 0 and s["counts"].get("ok", 0) > 0  # both roads taken


def test_the_harness_sees_each_kind_of_failure(tmp_path, monkeypatch):
    """The classifier is not blind: each failure it exists to find is reported as such."""
    assert F.classify("calibrate", "c", 0, "not json", "", b"", "", 0.1).kind == "stray-stdout"
    assert F.classify("calibrate", "c", 0, "{}", "", b"** On entry to DLASCL", "", 0.1).kind == "stray-stdout"
    assert (
        F.classify(
            "calibrate", "c", 2, "", "station: f: cannot process this input (ValueError: x)\n", b"", "", 0.1
        ).kind
        == "last-resort"
    )
    assert F.classify("calibrate", "c", 2, "", "station: a\nb\n", b"", "", 0.1).kind == "bad-exit"
    assert F.classify("calibrate", "c", None, "", "", b"", "KeyError: 'x'", 0.1).kind == "crash"
    assert (
        F.classify("calibrate", "c", 2, "", "station: f:3: column 'ax': 'x' is not a number\n", b"", "", 0.1).kind
        == "refused"
    )
    # a real hang: a worker that never answers is killed at the limit and reported
    runner = F.Runner(timeout_s=1.0)  # a sleeping worker: caught by the wall-time bound (10 x)
    monkeypatch.setattr(F, "_run_main", lambda argv: __import__("time").sleep(3600))
    try:
        assert runner.run("calibrate", str(tmp_path / "x.csv"), "sleeper").kind == "hang"
    finally:
        runner.close()


def test_mutators_change_the_file_and_keep_their_names():
    text = "# station-capture: 1\n# procedure: compass\nt,mx,my,mz\n" + "".join(
        f"{k * 0.1:.1f},{k},{-k},{2 * k}\n" for k in range(50)
    )
    rng = random.Random(4)
    changed = 0
    for _ in range(200):
        names, data = F.mutate(text, rng)
        assert names and all(n in {m.__name__[2:] for m in F.MUTATORS} for n in names.split("+"))
        changed += data != text.encode()
    assert changed >= 190  # a mutator that does nothing would hide behind the count


def test_mutating_a_file_cut_to_its_first_lines_still_works():
    text = "# station-capture: 1\n# procedure: ldv\nt,vl1\n"
    rng = random.Random(9)
    for _ in range(300):  # every mutator meets a file with no data line
        F.mutate(text[: rng.randrange(len(text))], rng)


# ------------------------------------------- the world's files and hostile ones (QA s27i)


@pytest.fixture(scope="module")
def world_bases(tmp_path_factory):
    """Two real captures cut short (Wang & Li's table, the imucal session) and a simulated P4."""
    folder = str(tmp_path_factory.mktemp("hostile"))
    real = F.real_bases(folder, max_rows=300)
    if not real:
        pytest.skip("../shared/data is not beside this clone")
    bases = {k: v for k, v in real.items() if k in ("real-table1", "real-imucal_ferraris")}
    bases.update(F.make_bases(folder, seed=5, names=("p4-static",)))
    return bases


def test_hostile_files_through_every_command_give_a_result_or_one_line(world_bases, tmp_path):
    """The special paths (empty file, folder, FIFO, /dev/zero, a 10 MB line, a 64 MiB hole) and
    captures mutated the hostile ways, through inspect, import --out, calibrate, calibrate
    --save (a real SQLite file) and diagnose: a result, or one line and exit 2; nothing
    half-written. The long run is `benchmarks/bench_fuzz.py --hostile N`."""
    outcomes = F.run_hostile_campaign(str(tmp_path), world_bases, n_mutated=6, seed=2027, timeout_s=TIMEOUT_S)
    s = F.summary(outcomes)
    assert s["failures"] == [], _report(outcomes)
    commands = {o.command for o in outcomes}
    assert commands == set(F.HOSTILE_COMMANDS)
    assert s["counts"].get("refused", 0) > 0 and s["counts"].get("ok", 0) > 0


def test_the_write_checks_see_what_a_command_left(tmp_path):
    """check_writes is not blind: a temporary left beside the output, an --out written by a
    refused import, a database changed by a refused save are each 'half-written'."""
    refused = F.Outcome("refused", "import", "c", 0.1, "station: x:1: bad")
    (tmp_path / "out.capture.csv").write_text("# station-capture: 1\n")
    assert F.check_writes("import", refused, str(tmp_path), (None, 0)).kind == "half-written"
    (tmp_path / "out.capture.csv").unlink()
    assert F.check_writes("import", refused, str(tmp_path), (None, 0)).kind == "refused"
    (tmp_path / ".out.capture.csv.1-0a0b0c0d.tmp").write_text("")
    assert F.check_writes("import", refused, str(tmp_path), (None, 0)).kind == "half-written"
    (tmp_path / ".out.capture.csv.1-0a0b0c0d.tmp").unlink()
    import sqlite3

    con = sqlite3.connect(tmp_path / "station.db")
    con.execute("create table calibrations (id integer)")
    con.commit()
    con.close()
    before = F._db_state(str(tmp_path / "station.db"))
    con = sqlite3.connect(tmp_path / "station.db")
    con.execute("insert into calibrations values (1)")
    con.commit()
    con.close()
    saved = F.Outcome("refused", "calibrate-save", "c", 0.1, "station: x:1: bad")
    assert F.check_writes("calibrate-save", saved, str(tmp_path), before).kind == "half-written"
    ok = F.Outcome("ok", "calibrate-save", "c", 0.1)
    assert F.check_writes("calibrate-save", ok, str(tmp_path), before).kind == "ok"


def test_hostile_mutators_change_the_file():
    text = "# station-capture: 1\n# procedure: compass\n# mag_unit: uT\nt,mx,my,mz\n" + "".join(
        f"{k * 0.1:.1f},{k},{-k},{2 * k}\n" for k in range(50)
    )
    rng = random.Random(27)
    for m in F.MUTATORS_HOSTILE[len(F.MUTATORS) :]:
        for _ in range(20):
            out = m(text, rng)
            assert (out if isinstance(out, bytes) else out.encode()) != text.encode(), m.__name__
