"""Bias-compensated least squares (BCLS) for noisy output lags in φ (eq. 3)."""

import numpy as np
from scipy.linalg import cho_factor, cho_solve

from ...._typing import Float2D


def output_lag_columns(n_outputs: int, na: int, d: int) -> np.ndarray:
    """Output of each φ column in the order of eq. (3) (per output its na lags first, as
    `lagged_matrix` builds φ), −1 for input lags and the
    constant."""
    return np.concatenate([np.repeat(np.arange(n_outputs), na),
                           np.full(d - n_outputs * na, -1)])


def bias_compensated_refit(phi: Float2D, target: Float2D, weights: np.ndarray,
                           lag_output: np.ndarray, n_iter: int = 30, rtol: float = 1e-6
                           ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """Weighted least-squares θ_i with the bias of noisy output lags compensated (BCLS).

    Measurement noise e_q (white, variance σ_q²) on the outputs enters φ through the output
    lags, and least squares is biased: E[ΦᵀWΦ]/Σw = Φ₀ᵀWΦ₀/Σw + D with D = diag(σ²_q(c)) on
    the output-lag columns c. The bias-compensated estimate (Sagara & Wada 1977; Zheng 1998)
    solves (ΦᵀWΦ − Σw·D) θ_i = ΦᵀWy. σ̂² comes from the least-squares residuals: with
    J_ip the weighted mean squared residual of output p under θ_i^LS,
    E J_ip = σ_p² + Σ_c σ²_q(c) θ_i,cp θ_i,cp^LS, pooled over the sub-models (weighted by
    Σw, one noise for all) and solved for σ² (m linear equations); θ and σ̂² are iterated
    to a fixed point.

    Guarded: when σ̂² is not finite and within (0, J̄_p] (J̄_p the pooled mean squared
    residual, which would be σ_p² if the lags were noise-free), the iteration does not
    converge in ``n_iter`` steps, or a compensated matrix is not positive definite, the
    affected θ_i (all of them, for σ̂²) keep least squares.

    Parameters
    ----------
    phi : ndarray of shape (n, d)
    target : ndarray of shape (n, m)
    weights : ndarray of shape (n, s)
        Weight of each row in each sub-model's fit (e.g. posterior probabilities).
    lag_output : ndarray of shape (d,)
        `output_lag_columns`: output of each column, −1 where noise-free.

    Returns
    -------
    thetas : ndarray of shape (s, d, m)
    sigma2 : ndarray of shape (m,), or None when σ̂² was implausible
    compensated : ndarray of shape (s,), bool
        Which θ_i are bias-compensated (the others are least squares).
    """
    m = target.shape[1]
    lag = lag_output >= 0
    total = weights.sum(axis=0)
    weighted = [phi * w[:, None] for w in weights.T]
    grams = np.stack([wp.T @ phi for wp in weighted])
    rhs = np.stack([wp.T @ target for wp in weighted])
    ls = np.stack([np.linalg.lstsq(g, r, rcond=None)[0] for g, r in zip(grams, rhs)])
    mean_sq = np.stack([w @ (target - phi @ th) ** 2 for w, th in zip(weights.T, ls)]
                       ) / total[:, None]
    share = total / total.sum()
    j_bar = share @ mean_sq
    owner = np.zeros((lag_output.size, m))  # column c → one-hot of its output q(c)
    owner[np.flatnonzero(lag), lag_output[lag]] = 1.0
    thetas = ls.copy()
    for _ in range(n_iter):
        # J̄_p = σ_p² + Σ_q σ_q² M_pq, M_pq = Σ_i share_i Σ_{c of q} θ_i,cp θ_i,cp^LS
        prod = np.einsum("i,icp,icp->cp", share, thetas, ls)
        new_sigma2 = np.linalg.solve(np.eye(m) + prod.T @ owner, j_bar)
        if not (np.all(np.isfinite(new_sigma2)) and np.all(new_sigma2 > 0)
                and np.all(new_sigma2 <= j_bar)):
            return ls, None, np.zeros(len(total), bool)
        diag = owner @ new_sigma2
        new, done = ls.copy(), np.ones(len(total), bool)
        for i in range(len(total)):
            try:
                new[i] = cho_solve(cho_factor(grams[i] - total[i] * np.diag(diag)), rhs[i])
            except np.linalg.LinAlgError:
                done[i] = False
        step = np.abs(new - thetas).max() / max(np.abs(new).max(), np.finfo(float).tiny)
        thetas, sigma2 = new, new_sigma2
        if step < rtol:
            return thetas, sigma2, done
    return ls, None, np.zeros(len(total), bool)
