"""Fitting the structures of `structures`: least squares per region, per-output
choice on held-out training experiments, and simulation-error refinement.

The route, for the estimators' ``form``, ``outputs`` and ``scheduling`` options:

1. With a refinement or a per-output choice (``SignScheduling(switch="select")``), the last
   training experiments are held out (the refinement's ``validation_fraction``, else
   `VALIDATION_FRACTION`); everything is fitted on the others.
2. Per group of outputs (each output alone when decoupled, all together when joint), each
   candidate structure is fitted: least squares in the user's regions (or one region), or
   the paper's steps 2–6 on the group's regressors ψ (clusters).
3. With a refinement, each candidate's parameters are refined on the free-run error of its
   group (`refine_outputs`), with the one-step error beside it when the
   refinement's ``one_step_weight`` is positive, the iterate chosen on the held-out
   experiments.
4. Per group, the candidate with the lowest free-run error on the held-out experiments is
   kept, a richer one only when it is lower by ``min_gain`` (relative) than the simpler one
   kept so far. The test record plays no part.
"""

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from sklearn.base import BaseEstimator

from .._typing import Float2D
from ..regressors import Regressors, build_regressors
from ..scoring.evaluation import WARMUP
from .output_error import VALIDATION_FRACTION, OutputFreeRuns, held_out, refine_outputs
from .partitions import ProjectedRegions, SignRegions
from .structures import (
    OutputModel,
    assign_params,
    output_lags,
    output_regressors,
    phi_names,
    switching_entries,
)


@dataclass(frozen=True)
class StructureFit:
    """A fitted structure and how it was chosen.

    Attributes
    ----------
    outputs : list of OutputModel
        Each output's structure and parameters (`structures`), in output order.
    validation_experiments : list of int
        Indices (in the training list) of the held-out experiments.
    validation_cost : dict
        Per output, each candidate's mean squared free-run error on them (empty without).
    refinement : list of dict
        Per group, the kept candidate's refinement (seconds, iterations, stop, costs).
    """

    outputs: list[OutputModel]
    validation_experiments: list[int]
    validation_cost: dict
    refinement: list[dict]


def _candidates(scheduling: BaseEstimator | None, cluster: Callable | None, affine: bool,
                coupling: str) -> list[str]:
    if scheduling is None:
        return ["linear"] if cluster is None else ["clustered"]
    if scheduling.switch == "offset" and not affine:
        raise ValueError("scheduling switch='offset' switches the constant term only and "
                         "needs affine=True")
    if scheduling.switch != "select":
        return [scheduling.switch]
    if coupling != "decoupled":
        raise ValueError("scheduling switch='select' chooses a structure per output and needs "
                         "outputs='decoupled' (with joint outputs the outputs' free runs "
                         "depend on each other)")
    return ["linear"] + (["offset"] if affine else []) + ["all"]


def clustered_models(group: list[int], reg: Regressors, parts: dict[int, tuple],
                     cluster: Callable) -> dict[int, OutputModel]:
    """The paper's steps 2–6 (``cluster``, see `fit_structure`) on a group's
    regressors ψ = M φ: one model per output of ``group``, every parameter switching between
    the clusters' regions, which the outputs share (one region map, the fitted steps kept
    with it).

    ``parts[j]`` is output j's ``(M, c, names)`` from `structures.output_regressors`
    (the same M for every output of the group); the clusters are fitted to y_j − c φ.
    """
    M = parts[group[0]][0]
    target = reg.target[:, group] - reg.phi @ np.array([parts[j][1] for j in group]).T
    thetas, steps = cluster(Regressors(phi=reg.phi @ M.T, target=target,
                                       experiment=reg.experiment, time=reg.time,
                                       n_inputs=reg.n_inputs))
    regions = ProjectedRegions(M, steps["regions"])
    return {j: OutputModel(M, parts[j][1], np.ones(M.shape[0], bool), len(thetas), regions,
                           "clustered", parts[j][2], p=thetas[:, :, jj].ravel(), steps=steps)
            for jj, j in enumerate(group)}


def _build(kind: str, group: list[int], reg: Regressors, shape: tuple, form: str,
           coupling: str, scheduling, cluster) -> dict[int, OutputModel]:
    m, r, na, nb, affine = shape
    lags = output_lags(na, form)
    names = phi_names(m, r, lags, nb, affine)
    parts = {j: output_regressors(j, m, r, na, nb, affine, form, coupling) for j in group}
    if kind == "clustered":
        return clustered_models(group, reg, parts, cluster)
    out = {}
    for j in group:
        M, c, psi_names = parts[j]
        if kind == "linear":
            om = OutputModel(M, c, np.zeros(len(psi_names), bool), 1, None, kind, psi_names)
        else:
            sign = SignRegions(scheduling.weights(j, names, lags))
            om = OutputModel(M, c, switching_entries(kind, psi_names), sign.n_regions_, sign,
                             kind, psi_names)
        out[j] = om.fit(reg.phi, reg.target[:, j])
    return out


def fit_structure(experiments: list[tuple[Float2D, Float2D]], na: int, nb: int, affine: bool,
                  form: str, coupling: str, scheduling: BaseEstimator | None = None,
                  refinement: BaseEstimator | None = None,
                  cluster: Callable | None = None, limits: Float2D | None = None
                  ) -> StructureFit:
    """Fit a structured model (see the module doc).

    Parameters
    ----------
    experiments : list of (u, y)
    na, nb : int
        Orders: in the velocity form, na increments (and the level y(k−1)).
    affine : bool
    form : {"level", "velocity"}
    coupling : {"joint", "decoupled"}
    scheduling : SignScheduling, optional
        User regions; without it one region (``cluster`` None) or clusters.
    refinement : OutputErrorRefinement, optional
    cluster : callable, optional
        ``cluster(reg)`` → (θ of shape (s, d, group size), the fitted steps by name): the
        paper's steps 2–6 on a group's regressors.
    limits : ndarray of shape (2, m), optional
        The outputs' limits (`pwa_pipeline.pwa.limits`): every free run, held out or
        refined, is clipped to them.

    Raises
    ------
    ValueError
        An incompatible choice (``"offset"`` without the constant, ``"select"`` with joint
        outputs, a scheduling variable naming no regressor), too few samples, or a
        starting model whose free run diverges (with a single candidate).
    """
    for step in filter(None, [scheduling, refinement]):
        step._validate_params()
    n, m, r = len(experiments), experiments[0][1].shape[1], experiments[0][0].shape[1]
    lags = output_lags(na, form)
    kinds = _candidates(scheduling, cluster, affine, coupling)
    min_gain = 0.0 if scheduling is None else scheduling.min_gain
    fraction = VALIDATION_FRACTION if refinement is None else refinement.validation_fraction
    n_val = held_out(n, fraction) if refinement is not None or len(kinds) > 1 else 0
    fit, held = experiments[:n - n_val], experiments[n - n_val:]
    reg = build_regressors(fit, lags, nb, affine)
    if reg.phi.shape[0] < reg.phi.shape[1]:
        raise ValueError(f"too few samples: {reg.phi.shape[0]} regressor rows for "
                         f"{reg.phi.shape[1]} regressor entries")
    warmup = max(lags, nb, WARMUP) if refinement is None else refinement.run_warmup(lags, nb)
    held_uy = ([e[0] for e in held], [e[1] for e in held]) if held else None
    groups = [[j] for j in range(m)] if coupling == "decoupled" else [list(range(m))]
    chosen: dict[int, OutputModel] = {}
    costs: dict[int, dict[str, float]] = {j: {} for j in range(m)}
    refined = []
    for group in groups:
        best = None
        for kind in kinds:
            models = _build(kind, group, reg, (m, r, na, nb, affine), form, coupling,
                            scheduling, cluster)
            info: dict = {}
            if refinement is not None:
                try:
                    res = refine_outputs(
                        models, group, [e[0] for e in fit], [e[1] for e in fit], lags, nb,
                        affine, warmup, validation=held_uy, max_iter=refinement.max_iter,
                        max_seconds=refinement.max_seconds, tol=refinement.tol,
                        patience=refinement.patience,
                        one_step_weight=refinement.one_step_weight, limits=limits)
                except ValueError:
                    if len(kinds) == 1:
                        raise
                    continue  # a candidate whose least-squares free run diverges
                assign_params(models, group, res.thetas)
                cost = res.validation_cost
                info = {"outputs": group, "structure": kind, "seconds": res.seconds,
                        "n_iter": res.n_iter, "stop": res.stop, "cost_start": res.cost_start,
                        "cost": res.cost, "one_step_start": res.one_step_start,
                        "one_step": res.one_step_cost}
            elif held_uy is not None:
                runs = OutputFreeRuns(*held_uy, lags, nb, affine, warmup, models, group,
                                      limits)
                cost = runs.simulate(np.concatenate([models[j].p for j in group]), False)[0]
            else:
                cost = np.nan
            for j in group:
                costs[j][kind] = float(cost)
            if best is None or cost < best[0] * (1 - min_gain):
                best = (cost, models, info)
        if best is None:
            raise ValueError(f"every candidate structure of output(s) {group} diverges in "
                             f"free run on the training data")
        chosen.update(best[1])
        if best[2]:
            refined.append(best[2])
    return StructureFit(outputs=[chosen[j] for j in range(m)],
                        validation_experiments=list(range(n - n_val, n)),
                        validation_cost=costs if n_val else {}, refinement=refined)
