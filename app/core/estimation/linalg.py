"""Covariance hygiene: symmetrise, a Cholesky factor that survives near-singular input, SPD repair.

Every covariance a filter step returns goes through ``symmetrise``; every square root goes
through ``robust_cholesky``, which adds growing diagonal jitter (and, as a last resort, clips the
eigenvalues) instead of raising on a matrix that round-off has made slightly indefinite.
"""

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

_JITTER_STEPS = 8
"""How many times the jitter grows tenfold before the eigenvalue repair takes over."""


def symmetrise(p: FloatArray) -> FloatArray:
    """(P + P^T) / 2 over the last two axes; shape (..., n, n) in and out, a new array."""
    return 0.5 * (p + p.swapaxes(-1, -2))


def nearest_spd(p: FloatArray, floor: float = 1e-12) -> FloatArray:
    """The symmetric matrix nearest to ``p`` whose eigenvalues are at least ``floor`` times its
    largest (and at least ``floor``); shape (n, n)."""
    sym = symmetrise(p)
    vals, vecs = np.linalg.eigh(sym)
    scale = max(float(np.max(np.abs(vals))), 1.0)
    vals = np.maximum(vals, floor * scale)
    return symmetrise((vecs * vals) @ vecs.T)


def robust_cholesky(p: FloatArray) -> FloatArray:
    """Lower Cholesky factor L (L L^T ~= P) of one (n, n) or a stack (k, n, n) of covariances.

    Tries the plain factorisation first; on failure repairs each failing matrix: symmetrise, add
    jitter eps * mean(diag) growing tenfold from 1e-12, then clip eigenvalues (``nearest_spd``).
    """
    try:
        out: FloatArray = np.linalg.cholesky(p).astype(np.float64, copy=False)
        return out
    except np.linalg.LinAlgError:
        pass
    if p.ndim == 3:
        return np.stack([robust_cholesky(m) for m in p])
    sym = symmetrise(p)
    n = sym.shape[0]
    scale = float(np.mean(np.abs(np.diag(sym))))
    if not np.isfinite(scale):
        raise np.linalg.LinAlgError("covariance has non-finite entries")
    scale = max(scale, 1e-300)
    eps = 1e-12
    for _ in range(_JITTER_STEPS):
        try:
            factor = np.linalg.cholesky(sym + eps * scale * np.eye(n))
            return factor.astype(np.float64, copy=False)
        except np.linalg.LinAlgError:
            eps *= 10.0
    return np.linalg.cholesky(nearest_spd(sym)).astype(np.float64, copy=False)


def is_spd(p: FloatArray) -> bool:
    """True when ``p`` (n, n) is finite, symmetric to 1e-9 relative, and Cholesky-factorisable."""
    if not np.all(np.isfinite(p)):
        return False
    scale = max(float(np.max(np.abs(p))), 1e-300)
    if float(np.max(np.abs(p - p.T))) > 1e-9 * scale:
        return False
    try:
        np.linalg.cholesky(p)
    except np.linalg.LinAlgError:
        return False
    return True
