"""Compiled kernel of the structure search's held-out free run (`pwa_pipeline.pwa.search`).

numba, because the search measures every candidate structure by simulating the held-out
experiments sample by sample (each sample's regressor φ̂(k) holds the outputs simulated
before it), and numpy pays that as a few calls per sample: about 0.1 s per candidate on the
robot's 13 held-out experiments, where the search measures about 1,100 candidates. One
compiled pass per experiment takes a few milliseconds. Compiled on first use and cached on
disk (``cache=True``, next to this file).

The candidates it runs are those whose region map has a compiled form
(`RegionMap.compiled`): linear, sign-scheduled
(`SignRegions`: region Σ_v 2^v [w_vᵀφ > 0]) and the
clusters' SVM regions (an argmax of affine scores); others are simulated by the search's
numpy loop.
"""

import numpy as np
from numba import njit

#: Region kinds of the kernels: the signs of scheduling variables, or an argmax of scores.
SIGN, ARGMAX = 0, 1


def pack_regions(forms: list[tuple[str, np.ndarray, np.ndarray]], d: int
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The kernels' region arrays (kinds, weights (G, V, D), bias (G, V), n_vars) of each
    simulated output's compiled form (`RegionMap.compiled`),
    unused rows zero."""
    v = max(1, max(len(w) for _, w, _ in forms))
    kinds = np.array([SIGN if kind == "sign" else ARGMAX for kind, _, _ in forms],
                     dtype=np.int64)
    weights, bias = np.zeros((len(forms), v, d)), np.zeros((len(forms), v))
    for g, (_, w, b) in enumerate(forms):
        weights[g, :len(w)], bias[g, :len(b)] = w, b
    return kinds, weights, bias, np.array([len(w) for _, w, _ in forms], dtype=np.int64)


@njit(nogil=True, cache=True)
def fill_phi(phi: np.ndarray, y: np.ndarray, u: np.ndarray, k: int, lags: int, nb: int
             ) -> None:
    """Write eq. (3)'s φ̂(k) of one experiment into ``phi``: per output of ``y`` (N, m) its
    ``lags`` lags (most recent first), per input of ``u`` (N, r) its ``nb`` lags, then 1."""
    i = 0
    for q in range(y.shape[1]):
        for lag in range(1, lags + 1):
            phi[i] = y[k - lag, q]
            i += 1
    for q in range(u.shape[1]):
        for lag in range(1, nb + 1):
            phi[i] = u[k - lag, q]
            i += 1
    phi[len(phi) - 1] = 1.0


@njit(nogil=True, cache=True)
def region_index(phi: np.ndarray, weights: np.ndarray, bias: np.ndarray, n_vars: int,
                 kind: int) -> int:
    """The region of φ: Σ_v 2^v [w_vᵀφ > 0] (``SIGN``), or the first v of largest
    w_vᵀφ + b_v (``ARGMAX``, as ``numpy.argmax``), over the first ``n_vars`` rows."""
    lam = 0
    best = -np.inf
    for v in range(n_vars):
        z = bias[v]
        for a in range(len(phi)):
            z += weights[v, a] * phi[a]
        if kind == SIGN:
            if z > 0:
                lam += 1 << v
        elif z > best:
            best, lam = z, v
    return lam


@njit(nogil=True, cache=True)
def clipped(s: float, lower: float, upper: float) -> float:
    """``s`` clipped to [lower, upper]; NaN stays NaN (the run's divergence is seen)."""
    if s < lower:
        return lower
    if s > upper:
        return upper
    return s


@njit(nogil=True, cache=True)
def region_free_run(y: np.ndarray, u: np.ndarray, lengths: np.ndarray, warmup: int,
                    lags: int, nb: int, outputs: np.ndarray, thetas: np.ndarray,
                    kinds: np.ndarray, weights: np.ndarray, bias: np.ndarray,
                    n_vars: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Sum of squared free-run errors of each simulated output, over every experiment.

    Each experiment e runs from sample ``warmup`` to ``lengths[e]``, its outputs before
    ``warmup`` and the outputs not in ``outputs`` taken as measured; φ̂(k) is eq. (3)'s, per
    output its ``lags`` lags (most recent first), per input its ``nb`` lags, then the
    constant 1.

    Parameters
    ----------
    y : ndarray of shape (E, N, m)
    u : ndarray of shape (E, N, r)
        Experiments padded to one length N.
    lengths : ndarray of shape (E,)
    warmup, lags, nb : int
    outputs : ndarray of shape (G,)
        The outputs that run free, each with its own model.
    thetas : ndarray of shape (G, R, D)
        Each simulated output's parameter row per region over φ (R at least 2^v; unused
        rows zero).
    kinds : ndarray of shape (G,)
        Each output's region kind (`SIGN`, `ARGMAX`; `region_index`).
    weights, bias : ndarrays of shape (G, V, D), (G, V)
        Each output's scheduling variables or scores w_vᵀφ + b_v (its first ``n_vars[g]``
        rows).
    n_vars : ndarray of shape (G,)
    lower, upper : ndarrays of shape (m,)
        Each output's limits (`pwa_pipeline.pwa.limits`; ±inf where none): the
        simulated value is clipped to them.

    Returns
    -------
    ndarray of shape (G,)
        Sums of squared errors; inf for every output once any simulated value is not
        finite (the run diverged).
    """
    d = thetas.shape[2]
    g = len(outputs)
    sse = np.zeros(g)
    phi = np.empty(d)
    yk = np.empty(g)
    for e in range(y.shape[0]):
        ysim = y[e].copy()
        for k in range(warmup, lengths[e]):
            fill_phi(phi, ysim, u[e], k, lags, nb)
            for jj in range(g):
                region = region_index(phi, weights[jj], bias[jj], n_vars[jj], kinds[jj])
                s = 0.0
                for a in range(d):
                    s += thetas[jj, region, a] * phi[a]
                yk[jj] = clipped(s, lower[outputs[jj]], upper[outputs[jj]])
            for jj in range(g):
                j = outputs[jj]
                err = yk[jj] - y[e, k, j]
                sse[jj] += err * err
                ysim[k, j] = yk[jj]
            for jj in range(g):
                if not np.isfinite(sse[jj]):
                    sse[:] = np.inf
                    return sse
    return sse
