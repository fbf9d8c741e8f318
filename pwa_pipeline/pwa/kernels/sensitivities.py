"""Compiled kernel of the output-error refinement's free run and its sensitivities
(`simulator`).

numba, because the refinement simulates the training experiments sample by sample, each
step propagating dŷ(k)/dp through the output lags of φ̂, and numpy pays that as a dozen
calls per sample: about 0.9 s per simulation of EMPS's 20,000-sample record, where a
refinement simulates 15 to 20 times and the structure search refines several candidates on
several folds. The kernel runs a block of time steps for every experiment and writes the
Jacobian rows of the block; the caller forms JᵀJ and Jᵀr from them with one matrix product
(BLAS) per block, so that a model with many parameters costs no more than with numpy.
Compiled on first use and cached on disk (``cache=True``, next to this file).

The models it runs are per-output models on an affine φ whose region maps have a compiled
form (`RegionMap.compiled`: linear, sign-scheduled, the
clusters' SVM regions); others are simulated by the numpy loop.
"""

import numpy as np
from numba import njit

from .free_run import clipped, fill_phi, region_index


@njit(nogil=True, cache=True)
def sensitivity_block(y: np.ndarray, u: np.ndarray, lengths: np.ndarray, warmup: int,
                      lags: int, nb: int, outputs: np.ndarray, thetas: np.ndarray,
                      gmat: np.ndarray, offsets: np.ndarray, kinds: np.ndarray,
                      weights: np.ndarray, bias: np.ndarray, n_vars: np.ndarray,
                      lower: np.ndarray, upper: np.ndarray, k0: int, k1: int,
                      ysim: np.ndarray, ring: np.ndarray, rows: np.ndarray,
                      residuals: np.ndarray,
                      sensitivities: bool) -> float:
    """The free run of time steps k0 ≤ k < k1 of every experiment: the sum of squared
    errors, and (with ``sensitivities``) the rows dŷ_j(k)/dp and residuals ŷ_j(k) − y_j(k).

    φ̂(k) is eq. (3)'s (per output its ``lags`` lags, most recent first, per input its
    ``nb`` lags, then 1); the outputs before ``warmup`` and those not in ``outputs`` are
    the measured ones. dŷ_j(k)/dp = φ̂(k)ᵀ G_j[λ_j(k)] + Σ_lag Σ_q θ_{j,λ_j(k)}[q, lag]
    dŷ_q(k − lag)/dp, the region held locally constant (as the numpy loop); 0 where ŷ_j(k)
    is clipped to one of its limits.

    Parameters
    ----------
    y, u : ndarrays of shape (E, N, m), (E, N, r)
        Experiments padded to one length N.
    lengths : ndarray of shape (E,)
    warmup, lags, nb : int
    outputs : ndarray of shape (G,)
        The outputs that run free.
    thetas : ndarray of shape (G, R, D)
        Each simulated output's parameter row per region over φ.
    gmat : ndarray of shape (G, R, D, P)
        dθ/dp per output and region (columns of output g between ``offsets[g]`` and
        ``offsets[g + 1]``).
    offsets : ndarray of shape (G + 1,)
    kinds, weights, bias, n_vars : ndarrays of shape (G,), (G, V, D), (G, V), (G,)
        Each output's regions (`region_index`).
    lower, upper : ndarrays of shape (m,)
        Each output's limits (`pwa_pipeline.pwa.limits`; ±inf where none).
    k0, k1 : int
        The block of time steps run.
    ysim : ndarray of shape (E, N, m)
        The simulated outputs so far (the measured ones before ``warmup``); updated.
    ring : ndarray of shape (E, lags + 1, G, P)
        dŷ/dp of the last ``lags`` steps, zeros before ``warmup``; updated.
    rows : ndarray of shape ((k1 − k0)·E·G, P)
    residuals : ndarray of shape ((k1 − k0)·E·G,)
        Written (zero rows past an experiment's end) when ``sensitivities``.
    sensitivities : bool

    Returns
    -------
    float
        The block's sum of squared errors (not finite once the run diverged).
    """
    n_exp = y.shape[0]
    n_out, d, n_par = len(outputs), thetas.shape[2], gmat.shape[3]
    phi = np.empty(d)
    yk = np.empty(n_out)
    region = np.zeros(n_out, dtype=np.int64)
    held = np.zeros(n_out, dtype=np.bool_)
    cost = 0.0
    for e in range(n_exp):
        for k in range(k0, k1):
            base = ((k - k0) * n_exp + e) * n_out
            if k >= lengths[e]:
                if sensitivities:
                    rows[base:base + n_out] = 0.0
                    residuals[base:base + n_out] = 0.0
                continue
            fill_phi(phi, ysim[e], u[e], k, lags, nb)
            for jj in range(n_out):
                lam = region_index(phi, weights[jj], bias[jj], n_vars[jj], kinds[jj])
                region[jj] = lam
                s = 0.0
                for a in range(d):
                    s += thetas[jj, lam, a] * phi[a]
                yk[jj] = clipped(s, lower[outputs[jj]], upper[outputs[jj]])
                held[jj] = yk[jj] != s
            for jj in range(n_out):
                err = yk[jj] - y[e, k, outputs[jj]]
                cost += err * err
                if sensitivities:
                    residuals[base + jj] = err
            if sensitivities:
                slot = k % (lags + 1)
                for jj in range(n_out):
                    row = rows[base + jj]
                    row[:] = 0.0
                    if held[jj]:  # a limit: ŷ_j(k) does not move with p
                        continue
                    lam = region[jj]
                    for a in range(d):
                        if phi[a] != 0.0:
                            for p in range(offsets[jj], offsets[jj + 1]):
                                row[p] += phi[a] * gmat[jj, lam, a, p]
                    for lag in range(1, lags + 1):
                        if k - lag < warmup:
                            break
                        prev = (k - lag) % (lags + 1)
                        for qq in range(n_out):
                            coef = thetas[jj, lam, outputs[qq] * lags + lag - 1]
                            if coef != 0.0:
                                for p in range(n_par):
                                    row[p] += coef * ring[e, prev, qq, p]
                for jj in range(n_out):
                    ring[e, slot, jj, :] = rows[base + jj]
            for jj in range(n_out):
                ysim[e, k, outputs[jj]] = yk[jj]
            if not np.isfinite(cost):
                return cost
    return cost
