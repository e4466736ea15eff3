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
    """A symmetric positive definite matrix near ``p`` (n, n), repaired in correlation space.

    P = D C D with D = diag(sqrt(diag P)); the eigenvalues of the correlation matrix C are
    clipped at ``floor``, so every variance keeps its own scale even when they span many orders
    of magnitude (metres next to a covariance grown over hours). Non-positive variances are
    raised to ``floor`` times the largest (or to ``floor``).
    """
    sym = symmetrise(p)
    diag = np.diag(sym).copy()
    top = max(float(np.max(diag)), 1.0) if diag.size else 1.0
    diag = np.where(diag > 0.0, diag, floor * top)
    d = np.sqrt(diag)
    corr = sym / np.outer(d, d)
    np.fill_diagonal(corr, 1.0)
    vals, vecs = np.linalg.eigh(corr)
    corr = (vecs * np.maximum(vals, floor)) @ vecs.T
    return symmetrise(corr * np.outer(d, d))


def ensure_spd(p: FloatArray) -> FloatArray:
    """``p`` (k, n, n) unchanged if every matrix factorises, else with the failing ones repaired
    by ``nearest_spd``."""
    try:
        np.linalg.cholesky(p)
        return p
    except np.linalg.LinAlgError:
        pass
    out = p.copy()
    for i in range(p.shape[0]):
        try:
            np.linalg.cholesky(p[i])
        except np.linalg.LinAlgError:
            out[i] = nearest_spd(p[i])
    return out


def robust_cholesky(p: FloatArray) -> FloatArray:
    """Lower Cholesky factor L (L L^T ~= P) of one (n, n) or a stack (k, n, n) of covariances.

    Tries the plain factorisation first; on failure repairs each failing matrix: symmetrise, add
    jitter eps * mean(diag) growing tenfold from 1e-12, then clip eigenvalues (``nearest_spd``).
    """
    try:
        out: FloatArray = np.linalg.cholesky(p).astype(np.float64, copy=False)
    except np.linalg.LinAlgError:
        pass
    else:
        if np.isfinite(out).all():
            return out
        raise np.linalg.LinAlgError("covariance has non-finite entries")
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
    if not np.isfinite(p).all():
        return False
    scale = max(float(np.max(np.abs(p))), 1e-300)
    if float(np.max(np.abs(p - p.T))) > 1e-9 * scale:
        return False
    try:
        np.linalg.cholesky(p)
    except np.linalg.LinAlgError:
        return False
    return True
