"""Run ``python -m station ARGS`` with every thread's Python stack written to the file named
by ``STATION_TEST_STACKS`` on SIGUSR1 (faulthandler), so that an end-to-end test that times
out can say where the app was, not only what the terminal showed. The app itself is unchanged."""

import faulthandler
import os
import runpy
import signal
import sys

_path = os.environ["STATION_TEST_STACKS"]
with open(_path + ".pid", "w") as f:
    f.write(str(os.getpid()))
_out = open(_path, "w")  # noqa: SIM115 - open for the process's life
faulthandler.register(signal.SIGUSR1, file=_out, all_threads=True)
sys.argv = ["station", *sys.argv[1:]]
runpy.run_module("station", run_name="__main__", alter_sys=True)
