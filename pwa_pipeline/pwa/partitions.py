"""Partitions of the regressor space into regions: the region maps of fitted models.

A PWA model chooses each output's sub-model by the region H_i that holds φ(k) (eq. 1). A
fitted model keeps, per group of outputs that switch together, one **region map**
([`RegionMap`][pwa_pipeline.pwa.RegionMap]): ``predict(phi)`` gives the region of each row of φ,
``n_regions_`` counts them, and ``halfspaces()`` writes each region as a polyhedron {φ : G_i φ ≤ q_i}, so
that [`to_state_space`][pwa_pipeline.control.to_state_space] exports any region map without knowing its
class. The regions are closed and may share boundaries; a point on a boundary belongs to the
lowest-numbered region that holds it (an argmax picks the lowest index among equal scores,
a sign test puts 0 with the negative side).

The maps here are those the estimators build themselves: one region (`SingleRegion`),
the signs of scheduling variables (`SignRegions`), a map fitted on an output group's
own regressor ψ = M φ (`ProjectedRegions`), and the regions of several groups at
once (`ProductRegions`). The paper's step 6 learns one from labelled rows
([`BaseRegions`][pwa_pipeline.pwa.steps.base.BaseRegions], e.g.
[`SVMRegions`][pwa_pipeline.pwa.SVMRegions], whose regions are an argmax of affine
scores, `argmax_halfspaces`).
"""

import itertools
from abc import ABC, abstractmethod
from collections.abc import Sequence

import numpy as np

from .._typing import Float2D

#: A region as rows (G, q) of G φ ≤ q over φ; None for a region that is never chosen.
Halfspaces = tuple[Float2D, np.ndarray] | None
#: A region map's compiled form (`RegionMap.compiled`): kind, W (v, D), b (v,).
CompiledForm = tuple[str, Float2D, np.ndarray]


class RegionMap(ABC):
    """A fitted partition of φ-space into ``n_regions_`` regions (see the module doc).

    Attributes
    ----------
    n_regions_ : int
    """

    n_regions_: int

    @abstractmethod
    def predict(self, phi: Float2D) -> np.ndarray:
        """The region 0 … s−1 of each row of ``phi`` (n, D); shape (n,)."""

    @abstractmethod
    def halfspaces(self) -> list[Halfspaces]:
        """Each region as (G, q) with region i = {φ : G φ ≤ q} over φ's D entries (the
        constant included), one entry per region, None for a region that is never chosen;
        ties go to the lowest-numbered region."""

    def compiled(self) -> CompiledForm | None:
        """The map as the compiled free runs read it (`kernels`):
        ``("sign", W, b)``, region Σ_v 2^v [W_vφ + b_v > 0], or ``("argmax", W, b)``,
        region argmax_v W_vφ + b_v (the first on ties); None (the default) when it has no
        such form, and the free runs call `predict`."""
        return None


def argmax_halfspaces(coef: Float2D, intercept: np.ndarray) -> list[Halfspaces]:
    """The regions of φ ∈ H_i ⇔ i = argmax_j (w_j·φ + b_j): H_i = {φ : (w_j − w_i)·φ ≤
    b_i − b_j for every j ≠ i}.

    Parameters
    ----------
    coef : ndarray of shape (s, D)
    intercept : ndarray of shape (s,)
        −inf marks a region that is never chosen (None in the result).

    Examples
    --------
    >>> G, q = argmax_halfspaces(np.array([[1.0], [-1.0]]), np.array([0.0, 0.0]))[0]
    >>> G.tolist(), q.tolist()  # region 0: −2 φ ≤ 0, i.e. φ ≥ 0
    ([[-2.0]], [0.0])
    """
    live = np.flatnonzero(np.isfinite(intercept))
    out: list[Halfspaces] = [None] * len(intercept)
    for i in live:
        others = live[live != i]
        out[i] = (coef[others] - coef[i], intercept[i] - intercept[others])
    return out


class SingleRegion(RegionMap):
    """All of φ-space, one region (a linear model).

    Parameters
    ----------
    n_features : int
        D, the entries of φ.
    """

    n_regions_ = 1

    def __init__(self, n_features: int):
        self.n_features = n_features

    def predict(self, phi: Float2D) -> np.ndarray:
        return np.zeros(len(phi), dtype=int)

    def compiled(self) -> CompiledForm:
        return "sign", np.zeros((0, self.n_features)), np.zeros(0)

    def halfspaces(self) -> list[Halfspaces]:
        return [(np.zeros((0, self.n_features)), np.zeros(0))]


class SignRegions(RegionMap):
    """The 2^v regions Σ_v 2^v [w_vᵀφ > 0] of the signs of v scheduling variables
    z_v = w_vᵀφ (`SignScheduling`).

    Parameters
    ----------
    weights : ndarray of shape (v, D)

    Examples
    --------
    >>> regions = SignRegions(np.array([[1.0, -1.0]]))
    >>> regions.predict(np.array([[2.0, 1.0], [1.0, 2.0]])).tolist()
    [1, 0]
    """

    def __init__(self, weights: Float2D):
        self.weights = np.asarray(weights, dtype=float)

    @property
    def n_regions_(self) -> int:
        """2^v."""
        return 2 ** self.weights.shape[0]

    def predict(self, phi: Float2D) -> np.ndarray:
        bits = (phi @ self.weights.T) > 0
        return bits @ (1 << np.arange(self.weights.shape[0]))

    def compiled(self) -> CompiledForm:
        return "sign", self.weights, np.zeros(len(self.weights))

    def halfspaces(self) -> list[Halfspaces]:
        """Region of bits β: w_vᵀφ ≤ 0 where β_v = 0, −w_vᵀφ ≤ 0 where β_v = 1."""
        v = self.weights.shape[0]
        out: list[Halfspaces] = []
        for label in range(2 ** v):
            bits = (label >> np.arange(v)) & 1
            out.append((self.weights * np.where(bits == 1, -1.0, 1.0)[:, None], np.zeros(v)))
        return out


class ProjectedRegions(RegionMap):
    """The regions of a map fitted on an output group's own regressor ψ = M φ: φ's region is
    ``regions.predict(M φ)``.

    Parameters
    ----------
    M : ndarray of shape (d, D)
    regions : fitted RegionMap over ψ
    """

    def __init__(self, M: Float2D, regions: RegionMap):
        self.M, self.regions = M, regions

    @property
    def n_regions_(self) -> int:
        return self.regions.n_regions_

    def predict(self, phi: Float2D) -> np.ndarray:
        return self.regions.predict(phi @ self.M.T)

    def compiled(self) -> CompiledForm | None:
        """The inner map's form over ψ = M φ, as a form over φ."""
        inner = self.regions.compiled()
        return None if inner is None else (inner[0], inner[1] @ self.M, inner[2])

    def halfspaces(self) -> list[Halfspaces]:
        """{ψ : G ψ ≤ q} is {φ : G M φ ≤ q}."""
        return [None if h is None else (h[0] @ self.M, h[1]) for h in self.regions.halfspaces()]


class ProductRegions(RegionMap):
    """The regions of several maps at once: one region per combination, numbered
    lexicographically (the first map's region varies slowest), so that region index
    Σ_g λ_g Π_{h>g} s_h.

    Parameters
    ----------
    maps : sequence of RegionMap
    """

    def __init__(self, maps: Sequence[RegionMap]):
        self.maps = list(maps)

    @property
    def sizes(self) -> list[int]:
        """Regions of each map."""
        return [m.n_regions_ for m in self.maps]

    @property
    def n_regions_(self) -> int:
        return int(np.prod(self.sizes))

    def predict(self, phi: Float2D) -> np.ndarray:
        index = np.zeros(len(phi), dtype=int)
        for part in self.maps:
            index = index * part.n_regions_ + part.predict(phi)
        return index

    def halfspaces(self) -> list[Halfspaces]:
        """Each combination's rows stacked (None where one of its regions is never
        chosen)."""
        out: list[Halfspaces] = []
        for cells in itertools.product(*(part.halfspaces() for part in self.maps)):
            out.append(None if any(c is None for c in cells) else
                       (np.vstack([c[0] for c in cells]), np.concatenate([c[1] for c in cells])))
        return out
