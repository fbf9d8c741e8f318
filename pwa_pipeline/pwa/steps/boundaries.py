"""Region boundaries placed where the sub-models' residuals switch (the default's step 6).

The region SVM of [`SVMRegions`][pwa_pipeline.pwa.SVMRegions] learns from hard labels and
a soft margin; near a boundary, where noise blurs which sub-model produced a row, its
hyperplanes sit a little off (98.4–99.6 % of fresh samples right with the true θ_i on the
section 5 system), and on switching systems that error dominates the free-run error.
[`ResidualRegions`][pwa_pipeline.pwa.ResidualRegions] starts from the SVM's hyperplanes and moves them to
maximise the likelihood of the outputs under the sub-models, the regions acting as a softmax gate of a
mixture of experts (`refine_boundaries`): the boundary settles where the residuals of
the two sub-models switch. A few EM steps then refit each sub-model on its rows weighted by
their posterior probability (`mixture_of_experts`), so that rows near a boundary,
which a hard label gives wholly to one side, weigh on each sub-model as the data say.

The modes switch on the noise-free regressors, but the measured output lags in φ carry the
output noise, which blurs the gate and costs about 0.3–0.5 % of fresh samples (with the true
θ_i and modes, the gate scores 99.46 % on measured φ of the section 5 system at 30 dB and
99.8 % on noise-free φ). From the first EM step on, the gate therefore sees φ with its
output lags denoised (`denoised_regressors`): each measured y(k−1) averaged with the
mixture's one-step prediction of it (with the true θ_i and modes one such step leaves
32–45 % of the noise variance on that system; each EM step repeats it on the last φ̃).
"""

from numbers import Integral, Real

import numpy as np
from scipy.optimize import minimize
from scipy.special import log_softmax, logsumexp
from sklearn.utils._param_validation import Interval

from ..._blas import single_threaded_blas
from ..._typing import Float2D
from .regions import SVMRegions
from .submodels import bias_compensated_refit, robust_noise_var


def _log_likelihood(phi: Float2D, target: Float2D, thetas: np.ndarray) -> np.ndarray:
    """−½ Σ_p r_ikp² / σ̂_p² of every row k under every sub-model i, shape (n, s); σ̂_p² is
    `robust_noise_var` of each row's best residual."""
    sq = (target[None] - phi @ thetas) ** 2  # (s, n, m)
    sigma2 = robust_noise_var(sq[np.argmin(sq.sum(axis=2), axis=0), np.arange(phi.shape[0])])
    return -0.5 * (sq / sigma2).sum(axis=2).T


def gate_log_likelihood(z: Float2D, log_lik: np.ndarray, ridge: float):
    """Objective and gradient of `refine_boundaries` for L-BFGS.

    Returns a function of the flattened gate parameters V (s, d + 1) giving
    −(1/n) Σ_k log Σ_i softmax_i(V z_k) exp(ℓ_ik) + (ridge/2)‖V without the last column‖²
    and its gradient. ``z`` has a trailing column of ones; ``log_lik`` is ℓ (n, s).
    """
    n, s = log_lik.shape

    def objective(v: np.ndarray) -> tuple[float, np.ndarray]:
        V = v.reshape(s, -1)
        log_gate = log_softmax(z @ V.T, axis=1)
        joint = log_gate + log_lik
        total = logsumexp(joint, axis=1, keepdims=True)
        responsibility = np.exp(joint - total)
        grad = (np.exp(log_gate) - responsibility).T @ z / n
        grad[:, :-1] += ridge * V[:, :-1]
        value = -total.sum() / n + 0.5 * ridge * float((V[:, :-1] ** 2).sum())
        return value, grad.ravel()

    return objective


def refine_boundaries(phi: Float2D, target: Float2D, thetas: np.ndarray, coef: Float2D,
                      intercept: np.ndarray, ridge: float = 1e-7, max_iter: int = 200,
                      gate_phi: Float2D | None = None) -> tuple[Float2D, np.ndarray, int]:
    """Move the hyperplanes of φ ∈ H_i ⇔ i = argmax_j (w_j·φ + b_j) to where the
    sub-models' residuals switch.

    The regions are read as a gate p_i(φ) = softmax_i(w_i·φ + b_i) of a mixture of the
    sub-models, each with Gaussian residuals of the noise variance σ̂_p²
    (`robust_noise_var` of each row's best residual), and
    (w, b) maximise the likelihood Σ_k log Σ_i p_i(φ_k) exp(−½ Σ_p r_ikp² / σ̂_p²) (the
    gating of a mixture of experts), by L-BFGS from the given hyperplanes, on z-scored φ
    with a small ridge on the slopes. The softmax is sharpened only as far as the data
    support, so a row whose residuals do not tell the sub-models apart pulls on no
    boundary, and rows where noise moved φ across a boundary pull it by their likelihood,
    not by a hinge. Regions with intercept −inf (never chosen) stay so.

    Parameters
    ----------
    phi : ndarray of shape (n, d)
    target : ndarray of shape (n, m)
    thetas : ndarray of shape (s, d, m)
    coef, intercept : ndarrays of shape (s, d) and (s,)
        The starting hyperplanes, e.g. an [`SVMRegions`][pwa_pipeline.pwa.SVMRegions]'s.
    ridge : float, default 1e-7
        Penalty on the squared slopes in z-scored units.
    max_iter : int, default 200
        L-BFGS iterations.
    gate_phi : ndarray of shape (n, d), optional
        The regressors the gate sees, when not φ (`denoised_regressors`); the
        residuals are φ's.

    Returns
    -------
    coef, intercept : the refined hyperplanes, in φ's units
    n_iter : int
        L-BFGS iterations run.
    """
    live = np.flatnonzero(np.isfinite(intercept))
    coef, intercept = coef.copy(), intercept.copy()
    if live.size <= 1:
        return coef, intercept, 0
    log_lik = _log_likelihood(phi, target, thetas[live])
    x = phi if gate_phi is None else gate_phi
    mean, std = x.mean(axis=0), x.std(axis=0)
    cols = std > 0
    z = np.column_stack([(x[:, cols] - mean[cols]) / std[cols], np.ones(x.shape[0])])
    v0 = np.column_stack([coef[np.ix_(live, np.flatnonzero(cols))] * std[cols],
                          intercept[live] + coef[live][:, cols] @ mean[cols]])
    result = minimize(gate_log_likelihood(z, log_lik, ridge), v0.ravel(), jac=True,
                      method="L-BFGS-B", options={"maxiter": max_iter})
    V = result.x.reshape(live.size, -1)
    w = V[:, :-1] / std[cols]
    coef[np.ix_(live, np.flatnonzero(cols))] = w
    intercept[live] = V[:, -1] - w @ mean[cols]
    return coef, intercept, int(result.nit)


def denoised_regressors(phi: Float2D, target: Float2D, thetas: np.ndarray, post: np.ndarray,
                        sigma2: np.ndarray, lag_output: np.ndarray, previous: np.ndarray,
                        gate_phi: Float2D) -> Float2D:
    """φ with its output lags replaced by estimates of the noise-free outputs.

    The measured y_q(k) = y⁰_q(k) + e_q(k) and the mixture's one-step prediction
    ŷ_q(k) = Σ_i q_ik θ_i,qᵀ φ̃(k) (posterior q_ik; φ̃ = ``gate_phi``, the last estimate)
    are averaged with inverse-variance weights: e_q has variance σ_q², and the
    prediction's error (the noise in φ̃'s output lags and the sub-models' errors) has the
    measured mean of (y_q − ŷ_q)² less σ_q² (at least σ_q²/1000), so a poor prediction is
    given little weight. Row k's lag-1 columns become row ``previous[k]``'s average,
    its lag-j columns that row's lag-(j − 1) columns; rows without a previous row
    (``previous`` −1, the first of each experiment) keep their measured lags.

    Parameters
    ----------
    phi, target : ndarrays of shape (n, d) and (n, m)
    thetas : ndarray of shape (s, d, m)
    post : ndarray of shape (n, s)
        Posterior probability of each row under each sub-model.
    sigma2 : ndarray of shape (m,)
        Output noise variances.
    lag_output : ndarray of shape (d,)
        `output_lag_columns`.
    previous : ndarray of shape (n,)
        Index of the row one sample earlier in the same experiment, −1 where none.
    gate_phi : ndarray of shape (n, d)
        φ̃ for the prediction (φ itself on the first call).
    """
    pred = np.einsum("ns,snm->nm", post, gate_phi @ thetas)
    pred_var = np.maximum(np.mean((target - pred) ** 2, axis=0) - sigma2, 1e-3 * sigma2)
    weight = pred_var / (pred_var + sigma2)
    clean = weight * target + (1 - weight) * pred
    out = phi.copy()
    has = np.flatnonzero(previous >= 0)
    for q in range(target.shape[1]):
        cols = np.flatnonzero(lag_output == q)  # lags 1 … na of output q, in order
        for j, c in enumerate(cols):
            out[has, c] = clean[previous[has], q] if j == 0 else out[previous[has], cols[j - 1]]
    return out


def previous_rows(experiment: np.ndarray) -> np.ndarray:
    """Index of the row one sample earlier in the same experiment (rows in time order within
    each, as `build_regressors` stacks them), −1 for each first row."""
    previous = np.arange(-1, experiment.size - 1)
    previous[np.flatnonzero(np.diff(experiment, prepend=np.nan) != 0)] = -1
    return previous


def mixture_of_experts(phi: Float2D, target: Float2D, thetas: np.ndarray, coef: Float2D,
                       intercept: np.ndarray, n_em: int = 3, ridge: float = 1e-7,
                       max_iter: int = 200, lag_output: np.ndarray | None = None,
                       previous: np.ndarray | None = None
                       ) -> tuple[np.ndarray, Float2D, np.ndarray, int, int]:
    """Regions and sub-models re-estimated together, as a mixture of experts gated by the
    regions, by ``n_em`` EM steps.

    Each step places the boundaries (`refine_boundaries`), takes the posterior
    probability of each row under each sub-model, q_ik ∝ p_i(φ_k) exp(−½ Σ_p r_ikp² / σ̂_p²),
    and refits every θ_i by least squares weighted by q_ik; the boundaries are placed once
    more at the end. A sub-model whose rows weigh less than d + 1 keeps its θ_i.

    With ``lag_output`` (`output_lag_columns`), the refit is
    bias-compensated for the measurement noise in the output lags
    (`bias_compensated_refit`, with the same weights); where its guard
    rejects the compensation the θ_i are weighted least squares. With ``previous`` too
    (`previous_rows`), every placement after the first fits the gate on φ with its
    output lags denoised by the refitted θ_i, the posterior and the compensation's σ̂²
    (`denoised_regressors`, its last result feeding the next prediction); the
    residuals stay φ's. Where σ̂² is implausible the gate keeps the last φ̃.

    Returns
    -------
    thetas, coef, intercept
        The refitted sub-models and hyperplanes.
    n_iter : int
        L-BFGS iterations over all boundary placements.
    n_uncompensated : int
        Sub-model refits that kept least squares (the guard; 0 without ``lag_output``).
    """
    thetas = thetas.copy()
    n_iter = n_uncompensated = 0
    d = phi.shape[1]
    gate_phi = phi
    for step in range(n_em + 1):
        coef, intercept, it = refine_boundaries(phi, target, thetas, coef, intercept, ridge,
                                                max_iter, gate_phi)
        n_iter += it
        live = np.flatnonzero(np.isfinite(intercept))
        if step == n_em or live.size <= 1:
            break
        joint = _log_likelihood(phi, target, thetas[live]) + log_softmax(
            gate_phi @ coef[live].T + intercept[live], axis=1)
        post = np.exp(joint - logsumexp(joint, axis=1, keepdims=True))
        fit = post.sum(axis=0) > d + 1
        if lag_output is not None and fit.any():
            refitted, sigma2, compensated = bias_compensated_refit(phi, target, post[:, fit],
                                                                   lag_output)
            thetas[live[fit]] = refitted
            n_uncompensated += int((~compensated).sum())
            if previous is not None and sigma2 is not None:
                gate_phi = denoised_regressors(phi, target, thetas[live], post, sigma2,
                                               lag_output, previous, gate_phi)
            continue
        for j, i in enumerate(live):
            if fit[j]:
                w = np.sqrt(post[:, j])[:, None]
                thetas[i] = np.linalg.lstsq(phi * w, target * w, rcond=None)[0]
    return thetas, coef, intercept, n_iter, n_uncompensated


class ResidualRegions(SVMRegions):
    """The library default's step 6: the regions of [`SVMRegions`][pwa_pipeline.pwa.SVMRegions], then
    their boundaries moved to where the sub-models' residuals switch
    (`refine_boundaries`).

    Given the outputs and the sub-models (``target`` and ``thetas`` at fit, which the
    estimator passes), the SVM's hyperplanes start the refinement, and the sub-models are
    refitted with the regions by ``n_em`` EM steps (`mixture_of_experts`); the
    estimator then uses those sub-models (``thetas_``). Without them (as inside the
    sub-model refinement's sweeps, `refine`) it is the SVM alone.
    Predicts as the SVM does, φ ∈ H_i ⇔ i = argmax_j (w_j·φ + b_j).

    Parameters
    ----------
    C, max_rows, random_state, tol
        Those of [`SVMRegions`][pwa_pipeline.pwa.SVMRegions].
    gate_ridge : float, default 1e-7
        ``ridge`` of `refine_boundaries`. 1e-5 held the slopes back from the sharp
        boundaries the data support (median region accuracy 0.2–0.5 points lower on tuning
        seeds with the true θ_i); 0 does as well as 1e-7 but is unbounded on separable rows.
    gate_max_rows : int, optional, default 20000
        Refine on at most this many rows (a seeded random choice). None: every row.
    gate_max_iter : int, default 200
        L-BFGS iterations of each boundary placement.
    n_em : int, default 3
        EM steps refitting the sub-models (0: boundaries only, the sub-models kept).
    compensate_bias : bool, default True
        Refit the sub-models in the EM steps by bias-compensated least squares
        (`bias_compensated_refit`): measurement noise on the outputs also
        sits in φ's output lags and biases least squares towards zero on them. Needs
        ``output_lags`` at fit (the estimator passes them on the joint level route only);
        without, least squares.
    denoise : bool, default True
        Fit the gate on φ with its output lags denoised (`denoised_regressors`) from
        the first EM step on. Needs ``output_lags`` and ``experiment`` at fit and
        ``compensate_bias`` (for σ̂²); the estimator passes them on the joint level route.

    Attributes
    ----------
    coef_, intercept_, n_regions_
        As [`SVMRegions`][pwa_pipeline.pwa.SVMRegions]'s, after the refinement.
    svm_coef_, svm_intercept_ : ndarrays
        The SVM's hyperplanes before it.
    thetas_ : ndarray of shape (s, d, m)
        The sub-models refitted with the regions (fits given ``thetas`` only).
    n_gate_iter_ : int
        L-BFGS iterations run (0: not refined).
    n_uncompensated_ : int
        EM refits of a sub-model that kept least squares because the compensation's guard
        rejected it (σ̂² implausible, no convergence, or a matrix not positive definite);
        0 without compensation.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> phi = rng.normal(size=(2000, 1))
    >>> thetas = np.array([[[1.0]], [[-1.0]]])
    >>> mode = (phi[:, 0] > 0.3).astype(int)
    >>> y = phi * thetas[mode, 0] + 0.05 * rng.normal(size=(2000, 1))
    >>> shifted = (phi[:, 0] > 0.6).astype(int)  # labels whose boundary is off by 0.3
    >>> regions = ResidualRegions().fit(phi, shifted, 2, target=y, thetas=thetas)
    >>> (w0, w1), (b0, b1) = regions.coef_[:, 0], regions.intercept_
    >>> bool(abs((b0 - b1) / (w1 - w0) - 0.3) < 0.03)  # the boundary back at 0.3
    True
    """

    _parameter_constraints: dict = {
        **SVMRegions._parameter_constraints,
        "gate_ridge": [Interval(Real, 0, None, closed="left")],
        "gate_max_rows": [Interval(Integral, 2, None, closed="left"), None],
        "gate_max_iter": [Interval(Integral, 0, None, closed="left")],
        "n_em": [Interval(Integral, 0, None, closed="left")],
        "compensate_bias": ["boolean"],
        "denoise": ["boolean"],
    }

    def __init__(self, C: float = 1.0, max_rows: int | None = 5000, random_state: int = 0,
                 tol: float = 1e-4, gate_ridge: float = 1e-7,
                 gate_max_rows: int | None = 20000, gate_max_iter: int = 200, n_em: int = 3,
                 compensate_bias: bool = True, denoise: bool = True):
        super().__init__(C=C, max_rows=max_rows, random_state=random_state, tol=tol)
        self.gate_ridge = gate_ridge
        self.gate_max_rows = gate_max_rows
        self.gate_max_iter = gate_max_iter
        self.n_em = n_em
        self.compensate_bias = compensate_bias
        self.denoise = denoise

    def fit(self, phi: Float2D, labels: np.ndarray, n_regions: int | None = None,
            sample_weight: np.ndarray | None = None, *, target: Float2D | None = None,
            thetas: np.ndarray | None = None, output_lags: np.ndarray | None = None,
            experiment: np.ndarray | None = None) -> "ResidualRegions":
        """Fit the SVM's hyperplanes on the labelled rows, then (with ``target`` and
        ``thetas``) refine them and the sub-models on the residuals.

        Parameters
        ----------
        phi, labels, n_regions, sample_weight
            As [`SVMRegions.fit`][pwa_pipeline.pwa.SVMRegions.fit].
        target : ndarray of shape (n, m), optional
            y(k) of each row.
        thetas : ndarray of shape (s, d, m), optional
            The sub-models, one per region.
        output_lags : ndarray of shape (d,), optional
            `output_lag_columns` of φ, for ``compensate_bias``.
        experiment : ndarray of shape (n,), optional
            Experiment of each row (rows in time order within each), for ``denoise``.

        Raises
        ------
        ValueError
            If only one of ``target`` and ``thetas`` is given, or ``thetas`` does not have
            one sub-model per region and φ's and y's widths, or ``output_lags`` is not one
            entry per column of φ.
        """
        super().fit(phi, labels, n_regions, sample_weight)
        self.svm_coef_, self.svm_intercept_ = self.coef_, self.intercept_
        self.n_gate_iter_ = self.n_uncompensated_ = 0
        if (target is None) != (thetas is None):
            raise ValueError("refining the regions needs both target and thetas, got only "
                             + ("target" if thetas is None else "thetas"))
        if target is None:
            return self
        target, thetas = np.asarray(target, float), np.asarray(thetas, float)
        if thetas.shape != (self.n_regions_, phi.shape[1], target.shape[1]):
            raise ValueError(f"thetas must have shape (regions, d, m) = ({self.n_regions_}, "
                             f"{phi.shape[1]}, {target.shape[1]}), got {thetas.shape}")
        if experiment is not None and np.shape(experiment) != (phi.shape[0],):
            raise ValueError(f"experiment must have one entry per row of phi "
                             f"({phi.shape[0]}), got shape {np.shape(experiment)}")
        if output_lags is not None and np.shape(output_lags) != (phi.shape[1],):
            raise ValueError(f"output_lags must have one entry per column of phi "
                             f"({phi.shape[1]}), got shape {np.shape(output_lags)}")
        lag_output = (np.asarray(output_lags, int)
                      if self.compensate_bias and output_lags is not None else None)
        rows = np.arange(phi.shape[0])
        if self.gate_max_rows is not None and rows.size > self.gate_max_rows:
            rows = np.sort(np.random.default_rng(self.random_state).choice(
                rows.size, self.gate_max_rows, replace=False))
        previous = None
        if self.denoise and lag_output is not None and experiment is not None:
            # the previous row of each kept row, as a position among the kept rows
            position = np.full(phi.shape[0] + 1, -1)
            position[rows] = np.arange(rows.size)
            previous = position[previous_rows(np.asarray(experiment))[rows]]
        # the gate's products are n × d by d × s (its L-BFGS objective on every row): BLAS
        # threads only wait, 2–4× the CPU time of one thread on the 20 dB records
        with single_threaded_blas():
            (self.thetas_, self.coef_, self.intercept_, self.n_gate_iter_,
             self.n_uncompensated_) = mixture_of_experts(
                phi[rows], target[rows], thetas, self.svm_coef_, self.svm_intercept_,
                self.n_em, self.gate_ridge, self.gate_max_iter, lag_output, previous)
        return self
