"""The calibration station application: CLI, capture files, device I/O, procedures, TUI."""

import os

__version__ = "0.1.0"

# One BLAS thread per process, unless the caller says otherwise (before numpy is first imported).
# The station's matrices are at most a few hundred rows: one thread is as fast on an idle machine,
# and on a busy one OpenBLAS's threads spin for a core that is taken (a 400-row eigh: 0.74 s with
# its default threads beside another process, 0.08 s with one; benchmarks/bench_blas_threads.py).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
