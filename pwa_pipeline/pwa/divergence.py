"""A fit's check of its own free run: a warning at fit time when the fitted model diverges on
the data it was fitted to ([`DivergenceWarning`][pwa_pipeline.pwa.DivergenceWarning]).

The paper's steps fit each sub-model by one-step least squares: nothing in them looks at the
free run, and a mode slightly unstable (spectral radius above 1) that the data leave often
enough in one step can carry the simulated output away when the model feeds itself
(e.g. a valve with stiction at orders (1, 1) with a constant). The fit then simulates its own
training experiments and warns, instead of leaving it to the held-out scores.
"""

import warnings

import numpy as np

from .._typing import Float2D
from ..control.conversion import mode_matrices
from ..control.stability import spectral_radii
from ..scoring.evaluation import DIVERGENCE

#: Samples of the training experiments simulated by the check, in file order: its cost
#: stays bounded on long records, and a divergence that starts only later is not seen.
MAX_CHECKED = 5000


class DivergenceWarning(UserWarning):
    """The fitted model's free run diverges on its own training data."""


def mode_radii(thetas: np.ndarray, m: int, r: int, lags: int, nb: int,
               affine: bool) -> np.ndarray:
    """ρ(A_i) of each sub-model θ_i (s, d, m) of eq. (1) over eq. (3)'s φ, A_i its state
    matrix of past outputs and inputs (`mode_matrices`, `spectral_radii`)."""
    return spectral_radii([mode_matrices(theta, m, r, lags, nb, affine)[0]
                           for theta in thetas])


def free_run_nrmse(model, experiments: list[tuple[Float2D, Float2D]],
                   max_samples: int = MAX_CHECKED) -> float:
    """The largest free-run NRMSE (eq. 21) of any output of `model` simulated from each
    training experiment's first samples, on at most `max_samples` samples in all (RMS
    error over those samples, divided by the output's standard deviation over every
    training sample); inf when the run leaves float64's range."""
    n0, left = model.n_initial_, max_samples
    sq, count = 0.0, 0
    for u, y in experiments:
        n = min(len(u), left)
        if n <= n0:
            continue
        left -= n
        err = model.simulate(u[:n], y[:n0])[n0:] - y[n0:n]
        if not np.all(np.isfinite(err)):
            return float("inf")
        sq, count = sq + (err ** 2).sum(axis=0), count + len(err)
    if not count:
        return 0.0
    scale = np.vstack([y for _, y in experiments]).std(axis=0)
    return float(np.max(np.sqrt(sq / count) / np.maximum(scale, np.finfo(float).tiny)))


def warn_if_diverging(model, experiments: list[tuple[Float2D, Float2D]],
                      divergence: float = DIVERGENCE) -> None:
    """Warn ([`DivergenceWarning`][pwa_pipeline.pwa.DivergenceWarning]) when the free run of the fitted
    `model` (on the paper's route: one output group over eq. 3's φ) on its training
    `experiments` has an NRMSE above `divergence` (`free_run_nrmse`, the evaluation's
    threshold for a diverged run), naming its unstable sub-models and what to try."""
    nrmse = free_run_nrmse(model, experiments)
    if nrmse <= divergence:
        return
    rho = mode_radii(model.thetas_, model.n_outputs_, model.n_inputs_, model.na,
                         model.nb, model.affine)
    unstable = ", ".join(f"{i} ({v:.4g})" for i, v in enumerate(rho) if v > 1)
    shown = "inf" if not np.isfinite(nrmse) else f"{nrmse:.3g}"
    warnings.warn(
        f"the fitted model diverges in free run on its own training data (NRMSE {shown} > "
        f"{divergence:g})" + (f"; sub-model(s) with spectral radius > 1: {unstable}"
                              if unstable else "")
        + f": its one-step fit does not simulate. Try PWARX.auto(na, nb) (a structure "
        f"judged by its free run) or other orders than na = {model.na}, nb = {model.nb}",
        DivergenceWarning, stacklevel=4)  # the caller of PWARX.fit
