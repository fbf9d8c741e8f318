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
        On the true system's regressor (`thetas` of the same shape as
        `model.thetas_[0]`; a larger regressor takes the truth through `embedded_thetas`).
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
    lags = model.output_lags_
    lag = n_initial(lags, model.nb)
    phi = build_regressors(pairs, lags, model.nb, model.affine).phi
    true = np.concatenate([m[lag:] for m in modes if len(m) > lag])
    return {"true_modes": len(thetas), "paired_submodels": int((mode_of >= 0).sum()),
            "max_param_error": float(np.nanmax(error)),
            "region_accuracy": float(np.mean(mode_of[model.regions_.predict(phi)] == true))}


def embedded_thetas(thetas: np.ndarray, m: int, r: int, na: int, nb: int, affine: bool,
                    lags: int, nb_to: int, affine_to: bool) -> np.ndarray | None:
    """A PWARX system's parameter matrices (orders `na`, `nb`, `affine`) written over a
    larger regressor of eq. (2)–(3) (`lags` output lags, `nb_to` input lags, the
    constant when `affine_to`): the system's entries where that regressor has them, zero
    for the lags and the constant it does not read. The system is the same model over
    either regressor, so a model fitted on the larger one (a structure search's φ of
    na + 1 lags and a constant) is compared with it there. None when the larger regressor
    lacks one of the system's entries.

    Parameters
    ----------
    thetas : ndarray of shape (s, m·na + r·nb (+1), m)
    m, r : int
        Outputs and inputs.
    """
    if lags < na or nb_to < nb or (affine and not affine_to):
        return None
    out = np.zeros((thetas.shape[0], m * lags + r * nb_to + int(affine_to), thetas.shape[2]))
    rows = [p * lags + j for p in range(m) for j in range(na)]
    rows += [m * lags + q * nb_to + j for q in range(r) for j in range(nb)]
    rows += [out.shape[1] - 1] if affine else []
    out[:, rows] = thetas
    return out
