"""One evaluation protocol for every model: one-step and free-run on held-out experiments.

Protocol. Each held-out experiment is scored on its own samples after a warm-up window of
``warmup`` samples (10 by default): the warm-up's measured outputs initialise the model (ARX
lags, or the state of a state-space model) and are excluded from the score. *One-step*:
every prediction uses measured past outputs. *Free run*: the model runs on the inputs alone
from the end of the warm-up to the end of the experiment, restarted at every experiment.
NRMSE (eq. 21), R² (eq. 22, standard form) and RMSE (data units) are computed per output on
the scored samples of all experiments together, and averaged over outputs (eq. 23–24).
A free run whose NRMSE exceeds ``divergence`` (10) or is not finite is flagged diverged; its
number is kept in the table all the same, and `Onset` says where it left the data: the first
scored sample whose error exceeds ``divergence`` standard deviations of its output (one
exists whenever an NRMSE exceeds ``divergence``), and the NRMSE of the samples before it.
Every page shows a diverged score one way, `score_text`'s: the bound the flag guarantees
and the word (``≥ 10 (diverged)``), never the number itself.

Data envelope. A model that records its training range (``signal_range_``: a fitted PWARX
or LinearARX) says, per scored sample and mode, whether its regressor
φ(k) left the training data's padded box
(`outside_envelope`): for one-step φ holds measured
outputs (the held-out data themselves lie outside the training data), for the free run the
run's own outputs (the run wandered off, or the data did). ``outside_share`` is the share of
the scored samples of all experiments so flagged, one value per mode (φ is shared by every
output); NaN for a model without a range (the subspace model has no regressor). A large
share means the scores measure extrapolation, not the identified dynamics.
"""

from dataclasses import dataclass
from numbers import Integral
from typing import Protocol

import numpy as np
import pandas as pd

from .._typing import Float2D
from .._validation import as_experiments
from .metrics import nrmse, r2_score, rmse

MODES = ("one_step", "free_run")
#: Free-run NRMSE above which a run is flagged diverged.
DIVERGENCE = 10.0


class Model(Protocol):
    """What the protocol needs of a fitted model (and, optionally, ``signal_range_`` and
    ``outside_envelope(u, y)`` for the share outside the data envelope)."""

    def predict(self, u, y, n_init: int | None = None): ...

    def simulate(self, u, y_init): ...


@dataclass(frozen=True)
class Onset:
    """Where a diverged free run left the data.

    Attributes
    ----------
    experiment : int
        The held-out experiment (from 0).
    sample : int
        The sample of that experiment (from 0, the warm-up counted) whose error first
        exceeds ``divergence`` standard deviations of its output, or is not finite.
    nrmse_before : float
        Mean over the outputs of the NRMSE (eq. 21, normalised as the evaluation's table) of
        the scored samples before that one, in all experiments up to it; NaN when it is the
        first scored sample.
    """

    experiment: int
    sample: int
    nrmse_before: float


@dataclass(frozen=True)
class Evaluation:
    """Scores of one model on one data set.

    Attributes
    ----------
    table : DataFrame
        Columns ``mode, output, nrmse, r2, rmse, diverged, outside_share``; ``output`` is
        an output's name or ``"mean"``; ``outside_share`` is the mode's share of scored
        samples outside the data envelope, the same on each of its rows (NaN: the model
        records no envelope).
    predictions : dict
        ``{"one_step": [...], "free_run": [...]}``, one array per experiment.
    onset : Onset or None
        Where the free run diverged; None when it did not.
    outside : dict or None
        ``{"one_step": [...], "free_run": [...]}``, per experiment a bool array of shape
        (N,): True where that mode's φ(k) leaves the data envelope (False on the warm-up);
        None when the model records no envelope.
    """

    table: pd.DataFrame
    predictions: dict[str, list[Float2D]]
    onset: Onset | None = None
    outside: dict[str, list[np.ndarray]] | None = None

    def mean(self, mode: str, metric: str = "nrmse") -> float:
        """The output-averaged ``metric`` of ``mode``."""
        row = self.table[(self.table["mode"] == mode) & (self.table["output"] == "mean")]
        return float(row[metric].iloc[0])

    def diverged(self, mode: str = "free_run") -> bool:
        """Whether the ``mode`` run diverged."""
        return bool(self.table.loc[self.table["mode"] == mode, "diverged"].any())

    def outside_share(self, mode: str = "free_run") -> float:
        """Share of the ``mode`` run's scored samples whose regressor left the data
        envelope; NaN when the model records none (or the table predates the column)."""
        if "outside_share" not in self.table:
            return float("nan")
        return self.mean(mode, "outside_share")


def score_text(value: float, metric: str, diverged: bool = False,
               divergence: float = DIVERGENCE) -> str:
    """A score as every page shows it: to 4 significant digits, or for a diverged run the
    bound its flag guarantees and the word, never the number itself (a 1e30 NRMSE says no
    more than that the run left the data, and sets the scale of any chart it enters).

    Parameters
    ----------
    value : float
        The score.
    metric : {"nrmse", "r2", "rmse"}
        Its metric: a diverged NRMSE shows as ``"≥ 10 (diverged)"``, R² as
        ``"≤ -99 (diverged)"`` (R² = 1 − NRMSE², eq. 21–22), RMSE as ``"diverged"`` (in the
        data's units, it has no bound).
    diverged : bool, default False
        Whether the run is flagged diverged (`Evaluation.diverged`).
    divergence : float, default 10
        The free-run NRMSE above which a run is flagged diverged.
    """
    if not diverged:
        return f"{value:.4g}"
    bound = {"nrmse": f"≥ {divergence:.4g} ", "r2": f"≤ {1 - divergence**2:.4g} ",
             "rmse": ""}[metric]
    return f"{bound}(diverged)" if bound else "diverged"


#: Warm-up samples of the evaluation protocol unless a data set sets its own.
WARMUP = 10


def evaluate(
    model: Model,
    u,
    y,
    warmup: int = WARMUP,
    output_names: list[str] | None = None,
    divergence: float = DIVERGENCE,
) -> Evaluation:
    """Score a fitted model by one-step prediction and free-run simulation (see module doc).

    Parameters
    ----------
    model : fitted PWARX, LinearARX or SubspaceSS
        Anything with ``predict(u, y, n_init)`` and ``simulate(u, y_init)``; with
        ``signal_range_`` and ``outside_envelope(u, y)`` as well, the share outside the data
        envelope is reported.
    u, y : arrays or lists of arrays
        Held-out experiments.
    warmup : int, default 10
        Initialising samples per experiment (at least 1), excluded from the score.
    output_names : list of str, optional
        One name per output; default ``y1, y2, ...``.
    divergence : float, default 10
        Free-run NRMSE above which a run is flagged diverged.

    Raises
    ------
    ValueError
        NaN or inf in the data, mismatched shapes, a ``warmup`` that is not an integer ≥ 1,
        a warm-up shorter than the model needs, an experiment not longer than the warm-up,
        or ``output_names`` whose length differs from the number of outputs, that repeat a
        name or that use ``"mean"``.
    """
    if not isinstance(warmup, Integral) or isinstance(warmup, bool) or warmup < 1:
        raise ValueError(f"warmup must be an integer >= 1, got {warmup!r}")
    pairs = as_experiments(u, y)
    m = pairs[0][1].shape[1]
    if output_names is not None and len(output_names) != m:
        raise ValueError(
            f"output_names has {len(output_names)} name(s) but y has {m} output(s)"
        )
    if output_names is not None and ("mean" in output_names
                                     or len(set(output_names)) != len(output_names)):
        raise ValueError(f"output_names must be distinct and not 'mean' (the average's row), "
                         f"got {list(output_names)}")
    short = [i for i, (ue, _) in enumerate(pairs) if ue.shape[0] <= warmup + 1]
    if short:
        raise ValueError(
            f"experiment(s) {short} have no more than warmup + 1 = {warmup + 1} samples"
        )
    us, ys = [p[0] for p in pairs], [p[1] for p in pairs]
    preds = {
        "one_step": [np.asarray(p) for p in model.predict(us, ys, n_init=warmup)],
        "free_run": [np.asarray(p) for p in model.simulate(us, [yy[:warmup] for yy in ys])],
    }
    names = [f"y{i + 1}" for i in range(m)] if output_names is None else list(output_names)
    truth = np.vstack([yy[warmup:] for yy in ys])
    outside = _outside(model, us, {"one_step": ys, "free_run": preds["free_run"]}, warmup)
    rows = []
    for mode in MODES:
        est = np.vstack([p[warmup:] for p in preds[mode]])
        scores = {"nrmse": nrmse(truth, est), "r2": r2_score(truth, est), "rmse": rmse(truth, est)}
        bad = ~np.isfinite(scores["nrmse"]) | (scores["nrmse"] > divergence)
        flag = bad if mode == "free_run" else np.zeros(m, bool)
        share = float("nan") if outside is None else \
            float(np.mean(np.concatenate([o[warmup:] for o in outside[mode]])))
        for i, name in enumerate(names):
            rows.append({"mode": mode, "output": name, **{k: float(v[i]) for k, v in scores.items()},
                         "diverged": bool(flag[i]), "outside_share": share})
        rows.append({"mode": mode, "output": "mean",
                     **{k: float(np.mean(v)) for k, v in scores.items()},
                     "diverged": bool(flag.any()), "outside_share": share})
    table = pd.DataFrame(rows)
    diverged = bool(table.loc[table["mode"] == "free_run", "diverged"].any())
    onset = _onset(ys, preds["free_run"], warmup, truth.std(axis=0), divergence) \
        if diverged else None
    return Evaluation(table=table, predictions=preds, onset=onset, outside=outside)


def _outside(model: Model, us: list[Float2D], outputs: dict[str, list[Float2D]],
             warmup: int) -> dict[str, list[np.ndarray]] | None:
    """Per mode and experiment, whether each sample's φ(k), built from ``outputs[mode]``
    (the measured outputs for one-step, the free run's for the free run), leaves the model's
    data envelope; the warm-up's samples False. None for a model without an envelope."""
    if getattr(model, "signal_range_", None) is None or not hasattr(model, "outside_envelope"):
        return None
    out = {}
    for mode, ys in outputs.items():
        flags = [np.asarray(f, bool).copy() for f in model.outside_envelope(us, ys)]
        for f in flags:
            f[:warmup] = False
        out[mode] = flags
    return out


def _onset(ys: list[Float2D], free: list[Float2D], warmup: int, scale: np.ndarray,
           divergence: float) -> Onset:
    """The `Onset` of a diverged free run ``free`` of the experiments ``ys``, errors
    normalised by ``scale`` (the standard deviation of each output's scored samples)."""
    squares, count = np.zeros(scale.shape), 0
    for e, (yy, est) in enumerate(zip(ys, free, strict=True)):
        with np.errstate(over="ignore", invalid="ignore"):
            err = np.abs(est[warmup:] - yy[warmup:]) / scale
        out = np.flatnonzero((~np.isfinite(err) | (err > divergence)).any(axis=1))
        stop = out[0] if out.size else err.shape[0]
        squares += np.sum(err[:stop] ** 2, axis=0)
        count += stop
        if out.size:
            before = float(np.mean(np.sqrt(squares / count))) if count else float("nan")
            return Onset(experiment=e, sample=warmup + int(stop), nrmse_before=before)
    # a non-finite mean without a bad sample cannot happen; the end is the honest answer
    return Onset(experiment=len(ys) - 1, sample=ys[-1].shape[0],
                 nrmse_before=float(np.mean(np.sqrt(squares / max(count, 1)))))
