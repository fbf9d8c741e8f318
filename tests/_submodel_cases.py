"""Small hand-built cases shared by the step-5 tests (tests/pwa/steps/test_submodels_*.py)."""

import numpy as np

from pwa_pipeline.pwa import DBSCANClustering, LocalLeastSquares

SIGMA = 0.05


def _two_modes(gap: float, n: int = 1200, seed: int = 0):
    """y = θ_iᵀ[x1, x2, 1] + e, mode 1 where x1 > 0; the affine terms differ by ``gap`` noise
    standard deviations, so the predictions of the two modes differ by exactly that."""
    rng = np.random.default_rng(seed)
    phi = np.column_stack([rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), np.ones(n)])
    mode = (phi[:, 0] > 0).astype(int)
    thetas = np.array([[[0.5], [1.0], [0.0]], [[0.5], [1.0], [gap * SIGMA]]])
    y = np.einsum("nd,ndm->nm", phi, thetas[mode]) + SIGMA * rng.normal(size=(n, 1))
    return phi, y, mode, thetas


def _close_modes(n=1500, seed=0, gap=0.15, sigma=0.05):
    """y(k) = a·y(k−1) + u(k−1), a = 0.5 where y(k−1) ≤ 0.2, 0.5 + gap above: the modes'
    predictions differ by 1–3 noise standard deviations, their rows split by a hyperplane."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1, 1, (n, 1))
    y = np.zeros((n, 1))
    mode = np.zeros(n, int)
    thetas = np.array([[[0.5], [1.0]], [[0.5 + gap], [1.0]]])
    for k in range(1, n):
        mode[k] = int(y[k - 1, 0] > 0.2)
        y[k] = np.r_[y[k - 1], u[k - 1]] @ thetas[mode[k]]
    return u, y + sigma * rng.normal(size=y.shape), thetas, mode


def _four_percent_mode():
    """A 4 % mode (79 of 2000 samples) whose rows the clusters give to its neighbour: φ, y,
    the local models and those clusters."""
    import copy

    thetas = np.array([[[0.5], [1.0]], [[-0.4], [1.0]], [[0.3], [2.0]]])
    rng = np.random.default_rng(0)
    n = 2000
    u = rng.uniform(-1, 1, (n, 1))
    y = np.zeros((n, 1))
    mode = np.zeros(n, int)
    for k in range(1, n):  # mode 2 where y(k−1) ≤ −0.8: 79 of 2000 samples
        mode[k] = 0 if y[k - 1, 0] > 0 else (1 if y[k - 1, 0] > -0.8 else 2)
        y[k] = np.r_[y[k - 1], u[k - 1]] @ thetas[mode[k]]
    y += 0.03 * rng.normal(size=y.shape)
    phi, target, mode = np.column_stack([y[:-1], u[:-1]]), y[1:], mode[1:]
    assert 0.03 < np.mean(mode == 2) < 0.05
    local = LocalLeastSquares().fit(phi, target)
    clustering = DBSCANClustering().fit(local, target)
    absorbed = copy.copy(clustering)
    absorbed.labels_ = np.where(clustering.labels_ >= 0, np.minimum(mode, 1), -1)
    return phi, target, local, absorbed


def _curved_mode(seed: int = 1, n: int = 200):
    """One mode y = 0.5x + 0.06x² + e, σ = 0.05, φ = [x, 1]: not affine, yet no PWA split."""
    rng = np.random.default_rng(seed)
    x = rng.uniform(-1, 1, n)
    phi = np.column_stack([x, np.ones(n)])
    y = (0.5 * x + 0.06 * x**2 + 0.05 * rng.normal(size=n))[:, None]
    return phi, y, LocalLeastSquares().fit(phi, y)


def _wide(gap: float, n: int = 2400, d: int = 12, seed: int = 0):
    """y = θ_iᵀφ + e on φ = [10 uniform columns, 1] (σ = 0.05), mode 1 where φ_0 > 0.2, its
    θ three entries ``gap`` above mode 0's: a search on 2,000 × 12 of φ, above SCREEN_SIZE."""
    rng = np.random.default_rng(seed)
    phi = np.column_stack([rng.uniform(-1, 1, (n, d - 1)), np.ones(n)])
    mode = (phi[:, 0] > 0.2).astype(int)
    thetas = np.repeat(rng.uniform(-1, 1, (1, d, 1)), 2, axis=0)
    thetas[1, 1:4, 0] += gap
    y = np.einsum("nd,ndm->nm", phi, thetas[mode]) + SIGMA * rng.normal(size=(n, 1))
    return phi, y, mode, LocalLeastSquares().fit(phi, y)


class _InOrder:
    """An executor that runs a submitted call only when its result is asked for (never when
    cancelled): the missed-mode search where the sequential loop ran it."""

    def __init__(self, workers: int):
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def submit(self, fn, *args):
        class Deferred:
            def cancel(self):
                return True

            def result(self):
                return fn(*args)

        return Deferred()
