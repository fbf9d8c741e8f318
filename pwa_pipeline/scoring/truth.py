"""Scores against a simulated system's ground truth: parameter error and region accuracy."""

import numpy as np

from .._validation import as_experiments
from ..regressors import build_regressors, n_initial
from .metrics import match_submodels


def ground_truth_scores(model, thetas: np.ndarray, u, y, modes) -> dict[str, float]:
    """How close a fitted PWARX model is to the system that generated the data.

    The estimated sub-models are paired with the true ones by their parameters
    ([`match_submodels`][pwa_pipeline.scoring.match_submodels]); a sample's region is right when
    the sub-model its estimated region H_i selects (step 6) is paired with the mode that
    produced it.

    Parameters
    ----------
    model : fitted PWARX
        With the true system's orders (``thetas`` of the same shape as ``model.thetas_[0]``).
    thetas : ndarray of shape (s, d, m)
        True parameter matrices.
    u, y : array-like or lists of array-likes
        Experiments to judge the regions on (fresh data for a fair figure).
    modes : ndarray of shape (N,) or list of them
        True mode (0-based) of every sample of each experiment.

    Returns
    -------
    dict
        ``true_modes`` (s), ``paired_submodels`` (estimated sub-models paired with a true
        one), ``max_param_error`` (largest absolute entry error over the pairs) and
        ``region_accuracy`` (share of regressor rows, as a fraction).

    Raises
    ------
    ValueError
        If the model's regressor length or outputs differ from the true system's.
    """
    if model.thetas_.shape[1:] != thetas.shape[1:]:
        raise ValueError(f"the model's parameter matrices are {model.thetas_.shape[1:]}, the "
                         f"true ones {thetas.shape[1:]}: the orders differ from the system's")
    mode_of, error = match_submodels(model.thetas_, thetas)
    pairs = as_experiments(u, y)
    modes = [np.asarray(modes)] if np.ndim(modes[0]) == 0 else [np.asarray(m) for m in modes]
    lag = n_initial(model.na, model.nb)
    phi = build_regressors(pairs, model.na, model.nb, model.affine).phi
    true = np.concatenate([m[lag:] for m in modes if len(m) > lag])
    return {"true_modes": len(thetas), "paired_submodels": int((mode_of >= 0).sum()),
            "max_param_error": float(np.nanmax(error)),
            "region_accuracy": float(np.mean(mode_of[model.regions_.predict(phi)] == true))}
