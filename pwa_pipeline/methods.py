"""The compared methods, named once: the pipeline's assets and checks, the comparison tables
and the benchmarks all read this registry."""

from collections.abc import Callable
from dataclasses import dataclass

from sklearn.base import BaseEstimator

from .baselines.linear import LinearARX
from .baselines.subspace import SubspaceSS
from .pwa.estimator import PWARX


@dataclass(frozen=True)
class Method:
    """One identification method.

    Attributes
    ----------
    name : str
        Key in tables, asset names (``<name>_model``, ``<name>_scores``) and MLflow tags.
    label : str
        For people: table columns and figure titles.
    build : callable
        ``build(pwa, baselines)`` → the unfitted estimator, from a set's PWARX (whose orders,
        form, outputs and refinement the linear ARX baseline shares) and the data set's
        ``[baselines.<dataset>]`` table.
    colour : str
        Its runs' colour in MLflow's UI (a colour of MLflow's own palette), one per method
        so that a comparison tells them apart.
    """

    name: str
    label: str
    build: Callable[[PWARX, dict], BaseEstimator]
    colour: str


METHODS: dict[str, Method] = {m.name: m for m in (
    Method("pwa", "PWA", lambda pwa, base: pwa, "#c83243"),
    Method("linear_arx", "linear ARX",
           lambda pwa, base: LinearARX(na=pwa.na, nb=pwa.nb, affine=pwa.affine, form=pwa.form,
                                       outputs=pwa.outputs, refinement=pwa.refinement),
           "#2272b4"),
    Method("subspace", "subspace",
           lambda pwa, base: SubspaceSS(**base.get("subspace", {}), warmup=base["warmup"]),
           "#308613"),
)}
