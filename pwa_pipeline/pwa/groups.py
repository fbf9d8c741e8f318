"""The fitted shape of every ARX-structured model: groups of outputs, each with one region
map and the sub-models of its regions.

Eq. (1) gives all outputs one partition, y(k) = θ_iᵀ φ(k) for φ(k) ∈ H_i. Machines often
switch per output (a joint's friction flips with its own velocity), so a fitted model holds
**output groups**: the outputs of a group switch together, by one region map over φ
(`partitions`), with parameter rows Θ_{g,i} over φ for each region i, so that

    ŷ_g(k) = Θ_{g,λ_g(φ(k))}ᵀ φ(k)    for every group g.

The paper's route and a linear model are one group of every output; a model with a
structure per output has a group per region map. Taken together the groups are again eq. (1)
with one mode per combination of the groups' regions (`modes`), numbered
lexicographically (the first group's region varies slowest).
"""

from collections.abc import Sequence
from dataclasses import dataclass, field

import joblib
import numpy as np

from .._typing import Float2D
from .limits import has_limits
from .partitions import ProductRegions, RegionMap, SingleRegion

#: Modes above which `modes` refuses to build the stacked parameter matrices (they
#: would take gigabytes; the groups predict without them).
MAX_MODES = 1 << 20


@dataclass(frozen=True)
class OutputGroup:
    """Outputs that switch together: one region map and the sub-models of its regions.

    Attributes
    ----------
    outputs : tuple of int
        The outputs' indices (0-based), increasing.
    regions : RegionMap
        The fitted region map over φ (eq. 2–3, the model's regressor).
    thetas : ndarray of shape (s, D, len(outputs))
        Each region's parameter rows over φ: ŷ_g = thetas[λ_g(φ)]ᵀ φ.
    steps : dict
        The fitted steps that found the regions and sub-models, by step name (the paper's
        ``local_models``, ``clustering``, ``submodels``, ``regions``, and the
        ``refinement``); empty where none ran (a linear group, scheduled regions). The record
        of the fit: prediction reads ``regions``, ``thetas`` and ``limits`` alone.
    limits : ndarray of shape (2, len(outputs)) or None
        The outputs' lower and upper limits (`limits`: ŷ is clipped to them), ±inf where
        an output has none; None: no output has any.
    """

    outputs: tuple[int, ...]
    regions: RegionMap
    thetas: np.ndarray
    steps: dict = field(default_factory=dict, compare=False, repr=False)
    limits: np.ndarray | None = field(default=None, compare=False)

    @property
    def n_regions(self) -> int:
        """s, the group's regions (and sub-models)."""
        return self.regions.n_regions_

    def predict_phi(self, phi: Float2D) -> Float2D:
        """ŷ of the group's outputs for each row of φ: shape (n, len(outputs)), clipped to
        the outputs' ``limits``."""
        if isinstance(self.regions, SingleRegion):  # no partition: one matrix product
            out = phi @ self.thetas[0]
        else:
            out = np.einsum("nd,ndm->nm", phi, self.thetas[self.regions.predict(phi)])
        return out if self.limits is None else np.clip(out, self.limits[0], self.limits[1])


def predict_groups(groups: Sequence[OutputGroup], phi: Float2D, n_outputs: int) -> Float2D:
    """ŷ(k) of every output for each row of φ: shape (n, m)."""
    if len(groups) == 1 and groups[0].outputs == tuple(range(n_outputs)):
        return groups[0].predict_phi(phi)
    out = np.empty((phi.shape[0], n_outputs))
    for group in groups:
        out[:, group.outputs] = group.predict_phi(phi)
    return out


def modes(groups: Sequence[OutputGroup], n_outputs: int) -> tuple[RegionMap, np.ndarray]:
    """The groups as one PWA model of eq. (1): its region map and parameter matrices.

    Returns
    -------
    regions : RegionMap
        The single group's map, or `ProductRegions` of the groups'.
    thetas : ndarray of shape (S, D, m)
        θ_i of every mode i (S the product of the groups' region counts).

    Raises
    ------
    ValueError
        Above `MAX_MODES` modes.
    """
    if len(groups) == 1:
        return groups[0].regions, groups[0].thetas
    sizes = [g.n_regions for g in groups]
    count = int(np.prod(sizes, dtype=float))
    if count > MAX_MODES:
        raise ValueError(f"the model's {len(groups)} output groups with {sizes} regions make "
                         f"{count:,} modes, too many to stack as one parameter array; use "
                         f"groups_, each group's regions and parameters")
    d = groups[0].thetas.shape[1]
    thetas = np.empty((count, d, n_outputs))
    for mode, regions in enumerate(np.ndindex(*sizes)):
        for group, i in zip(groups, regions, strict=True):
            thetas[mode][:, group.outputs] = group.thetas[i]
    return ProductRegions([g.regions for g in groups]), thetas


def grouped(regions: Sequence[RegionMap], thetas: Sequence[np.ndarray],
            steps: Sequence[dict] | None = None, limits: np.ndarray | None = None
            ) -> list[OutputGroup]:
    """Output groups from each output's region map and parameter rows: outputs whose maps
    are the same object or equal (same class and content) form one group.

    Parameters
    ----------
    regions : sequence of RegionMap
        Output j's map.
    thetas : sequence of ndarrays of shape (s_j, D)
        Output j's rows over φ.
    steps : sequence of dict, optional
        Output j's fitted steps (a group keeps its first output's).
    limits : ndarray of shape (2, m), optional
        Each output's lower and upper limit (`limits`), ±inf where none.
    """
    keys: list[str] = []
    members: dict[str, list[int]] = {}
    for j, region_map in enumerate(regions):
        key = joblib.hash(region_map)
        if key not in members:
            keys.append(key)
            members[key] = []
        members[key].append(j)
    groups = []
    for key in keys:
        outs = members[key]
        groups.append(OutputGroup(
            outputs=tuple(outs), regions=regions[outs[0]],
            thetas=np.stack([thetas[j] for j in outs], axis=2),
            steps={} if steps is None else steps[outs[0]],
            limits=limits[:, outs] if has_limits(limits) else None))
    return groups
