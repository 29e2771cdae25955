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
    monkeypatch.setattr(F, "_run_main", lambda command, path: __import__("time").sleep(3600))
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
