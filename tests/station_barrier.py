"""`python tests/station_barrier.py DIR ARGS...`: the real `station ARGS` in its own process, held
once, right after its first judgement against the database (``station.store.judge``): it
creates ``DIR/judged`` and waits until ``DIR/go`` exists. A test thus puts another process's
save between one process's judgement and its save, on conditions, not sleeps."""

from __future__ import annotations

import pathlib
import runpy
import sys
import time

WAIT_S = 120.0  # the longest a held process waits for its go (a test that forgot it fails, not hangs)


ROOT = pathlib.Path(__file__).resolve().parents[1]


def main() -> None:
    sys.path.insert(0, str(ROOT))  # the tree under test (run as a script, its folder is tests/)
    folder = pathlib.Path(sys.argv[1])
    sys.argv = ["station", *sys.argv[2:]]
    import station.store as store

    judge = store.judge
    held = []

    def held_judge(*args, **kw):
        out = judge(*args, **kw)
        if not held:
            held.append(True)
            (folder / "judged").touch()
            end = time.monotonic() + WAIT_S
            while not (folder / "go").exists():
                if time.monotonic() > end:
                    raise SystemExit(f"station_barrier: no {folder / 'go'} in {WAIT_S:g} s")
                time.sleep(0.01)
        return out

    store.judge = held_judge
    runpy.run_module("station", run_name="__main__", alter_sys=True)


if __name__ == "__main__":
    main()
