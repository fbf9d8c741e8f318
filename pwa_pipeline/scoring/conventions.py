"""Free-run scores in the conventions the literature on the KUKA benchmark uses.

Published figures differ in three ways: the normalisation (σ of the output, its range
max − min, or none), whether the free run restarts at every experiment or runs the whole test
record once, and the warm-up window. A number is comparable only with numbers of the same
convention:

- ``project``: this project's protocol ([`evaluate`][pwa_pipeline.scoring.evaluate]):
  RMSE / σ per output (eq. 21), restarted at every held-out experiment after a warm-up
  of 10 measured samples, averaged over outputs (eq. 23).
- ``range_single_run``: RMSE / (max − min) of each output over the whole test record, the
  record simulated once as one experiment (its segments end to end) from its first
  ``warmup`` measured samples, averaged over outputs — the convention of Fañanás-Anaya et
  al. (2025, Table VI), who start from the initial state; the warm-up samples are not scored.
- ``window_rmse``: RMSE in the outputs' units (degrees for the robot) of the whole test
  record simulated once after a window of 100 measured samples, per output and averaged —
  the convention of identibench.
"""

from dataclasses import dataclass

import numpy as np

from .._validation import as_experiments
from .evaluation import WARMUP, Model, evaluate
from .metrics import rmse


@dataclass(frozen=True)
class Convention:
    """How one convention scores a free run.

    Attributes
    ----------
    name : str
    normalisation : str
        ``"std"``, ``"range"`` or ``"none"`` (output units).
    restart : bool
        Whether the free run restarts at every experiment.
    warmup : int
        Measured samples that initialise the run and are not scored.
    unit : str
        The unit of an unnormalised score (``"mm"``); empty: the outputs' own.
    scale : float
        Factor from the outputs' unit to ``unit`` (1000 from m to mm).
    """

    name: str
    normalisation: str
    restart: bool
    warmup: int
    unit: str = ""
    scale: float = 1.0


CONVENTIONS = {c.name: c for c in (
    Convention("project", "std", restart=True, warmup=WARMUP),
    Convention("range_single_run", "range", restart=False, warmup=WARMUP),
    Convention("window_rmse", "none", restart=False, warmup=100),
)}


def single_run_scores(model: Model, u, y, convention: Convention) -> np.ndarray:
    """Per-output free-run score of ``model`` on the test record run once.

    Parameters
    ----------
    model : fitted estimator with simulate(u, y_init)
    u, y : array-like or lists of array-likes
        The test record; a list of experiments is joined end to end into one.
    convention : Convention
        One with ``restart=False``.

    Returns
    -------
    ndarray of shape (m,)
        RMSE / range, or RMSE in the convention's unit, per output, over the samples after
        the warm-up; inf where the run diverged.
    """
    if convention.restart:
        raise ValueError(f"convention {convention.name!r} restarts at every experiment: use "
                         f"evaluate()")
    pairs = as_experiments(u, y)
    ua = np.vstack([p[0] for p in pairs])
    ya = np.vstack([p[1] for p in pairs])
    w = convention.warmup
    sim = np.asarray(model.simulate(ua, ya[:w]))
    err = rmse(ya[w:], sim[w:])
    err = np.where(np.isfinite(err), err, np.inf)
    if convention.normalisation == "range":
        return err / (ya.max(axis=0) - ya.min(axis=0))
    return err * convention.scale


def convention_scores(model: Model, u, y) -> dict[str, float]:
    """The mean free-run score in every convention of `CONVENTIONS`."""
    out = {}
    for name, convention in CONVENTIONS.items():
        if convention.restart:
            out[name] = evaluate(model, u, y, warmup=convention.warmup).mean("free_run")
        else:
            out[name] = float(np.mean(single_run_scores(model, u, y, convention)))
    return out
