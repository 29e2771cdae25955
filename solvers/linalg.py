"""Finite-checked wrappers of the LAPACK calls that can misbehave on NaN or infinity.

``numpy.linalg.lstsq`` (LAPACK ``gelsd``) given a NaN or an infinity can print
``** On entry to DLASCL parameter number 4 had an illegal value`` on stdout and never
return; ``svd`` raises or returns NaN. Every solver goes through these instead, so a
non-finite intermediate (an overflowing square of an absurd reading) becomes
:class:`solvers.errors.NotFinite` with a message, at once.
"""

from __future__ import annotations

import numpy as np

from solvers.errors import NotFinite


def _check(what: str, *arrays) -> None:
    for a in arrays:
        if not np.all(np.isfinite(a)):
            raise NotFinite(
                f"{what}: the numbers overflowed or are not finite "
                "(values far beyond the sensor's range, or a degenerate input)"
            )


def lstsq(a, b, rcond=None):
    """``numpy.linalg.lstsq`` that refuses NaN/inf in ``a`` or ``b`` instead of hanging."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    _check("least squares", a, b)
    return np.linalg.lstsq(a, b, rcond=rcond)


def svd(a, full_matrices=True, compute_uv=True):
    """``numpy.linalg.svd`` that refuses NaN/inf in ``a``."""
    a = np.asarray(a, dtype=float)
    _check("singular value decomposition", a)
    return np.linalg.svd(a, full_matrices=full_matrices, compute_uv=compute_uv)


def eigh(a):
    """``numpy.linalg.eigh`` that refuses NaN/inf in ``a``."""
    a = np.asarray(a, dtype=float)
    _check("eigen decomposition", a)
    return np.linalg.eigh(a)


def cholesky_lower(a):
    """The lower Cholesky factor of the symmetric positive-definite ``a``, NaN/inf refused."""
    from scipy.linalg import cholesky

    a = np.asarray(a, dtype=float)
    _check("Cholesky factorisation", a)
    return cholesky(a, lower=True, check_finite=False)


def solve_lower(L, b):
    """``L⁻¹ b`` for a lower-triangular ``L`` (forward substitution), NaN/inf refused."""
    from scipy.linalg import solve_triangular

    L, b = np.asarray(L, dtype=float), np.asarray(b, dtype=float)
    _check("triangular solve", L, b)
    return solve_triangular(L, b, lower=True, check_finite=False)
