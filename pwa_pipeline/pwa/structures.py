"""Model structures for machines: velocity form, one model per output, user regions.

Every structure is written over the standard regressor φ(k) of eq. (2)–(3) (levels, L lags
per output, nb per input, the constant), so that prediction and simulation stay those of
`ARXModelBase`. Output j has its own regressor ψ_j(k) = M_j φ(k), target
y_j(k) − c_jᵀφ(k), regions λ_j(φ) and sub-models θ_{j,i}:

    ŷ_j(k) = c_jᵀ φ(k) + θ_{j,λ_j(φ(k))}ᵀ M_j φ(k).

- ``form="level"``: ψ holds the output lags y(k−1) … y(k−na) as eq. (3), c_j = 0.
- ``form="velocity"`` (increment form): ψ holds the increments Δy(k−1) … Δy(k−na),
  Δy(k) = y(k) − y(k−1), and the level y(k−1); the target is Δy_j(k), c_j picks y_j(k−1)
  (the model integrates its increments). φ then needs L = na + 1 output lags.
- ``outputs="joint"``: ψ_j holds every output's lags (the MIMO model of eq. 1);
  ``outputs="decoupled"``: output j's own lags only (one MISO model per output), so each
  output's free run depends on the inputs and itself alone.
- Every ψ_j holds every input's lags u(k−1) … u(k−nb), and 1 when ``affine``.

The sub-models' parameters are a vector p_j with θ_{j,i} = A_i p_j: all entries switching
(``"all"``, or clusters), only the constant (``"offset"``) or none (one linear model). The
effective parameter row over φ is Θ_{j,i} = c_j + M_jᵀ A_i p_j.

``"continuous"`` is a continuous PWA map, a linear model plus a hinge max(0, z_v) of each
scheduling variable z_v = w_vᵀφ (Breiman's hinging hyperplanes with the hinges fixed):

    ŷ_j(k) = c_jᵀ φ(k) + θ_jᵀ M_j φ(k) + Σ_v γ_v max(0, w_vᵀ φ(k)),

p_j = (θ_j, γ). In the region of bits β (z_v > 0 where β_v = 1) the map is affine,
Θ_{j,β} = c_j + M_jᵀ θ_j + Σ_v β_v γ_v w_v, and two regions that share a boundary z_v = 0
agree on it: a smooth nonlinearity (a square-root outflow, a saturation that sets in
gradually) gets slopes that bend, not offsets that jump.
"""

from dataclasses import dataclass, field

import numpy as np

from .._typing import Float2D
from .groups import OutputGroup, grouped
from .partitions import RegionMap, SingleRegion

#: Regressor forms and output couplings of the structured estimators.
FORMS = ("level", "velocity")
COUPLINGS = ("joint", "decoupled")


def output_lags(na: int, form: str) -> int:
    """L, the output lags φ needs: na, or na + 1 in the velocity form."""
    return na + int(form == "velocity")


def phi_names(m: int, r: int, lags: int, nb: int, affine: bool) -> list[str]:
    """φ's entry names with outputs ``y1…`` and inputs ``u1…`` (eq. 3 order)."""
    names = [f"y{q + 1}(k-{j})" for q in range(m) for j in range(1, lags + 1)]
    names += [f"u{q + 1}(k-{j})" for q in range(r) for j in range(1, nb + 1)]
    return names + (["1"] if affine else [])


def output_regressors(j: int, m: int, r: int, na: int, nb: int, affine: bool, form: str,
                      coupling: str, phi_lags: int | None = None,
                      phi_nb: int | None = None) -> tuple[Float2D, np.ndarray, list[str]]:
    """M_j, c_j and ψ_j's entry names for output j (see the module doc).

    Parameters
    ----------
    phi_lags, phi_nb : int, optional
        The output and input lags of φ when φ holds more than ψ_j needs (a structure
        search builds φ once at its largest orders and picks lower ones from it); by
        default `output_lags` of ``na`` and ``nb``.

    Returns
    -------
    M : ndarray of shape (d_j, D)
    c : ndarray of shape (D,)
    names : list of str
    """
    lags = output_lags(na, form) if phi_lags is None else phi_lags
    phi_nb = nb if phi_nb is None else phi_nb
    if lags < output_lags(na, form) or phi_nb < nb:
        raise ValueError(f"φ with {lags} output and {phi_nb} input lags cannot hold a "
                         f"{form}-form regressor of orders ({na}, {nb})")
    dim = (m * lags + r * phi_nb + int(affine))
    own = [j] if coupling == "decoupled" else list(range(m))
    rows, names = [], []

    def unit(i: int) -> np.ndarray:
        e = np.zeros(dim)
        e[i] = 1.0
        return e

    def y(q: int, lag: int) -> int:
        return q * lags + lag - 1

    for q in own:
        for lag in range(1, na + 1):
            if form == "velocity":
                rows.append(unit(y(q, lag)) - unit(y(q, lag + 1)))
                names.append(f"Δy{q + 1}(k-{lag})")
            else:
                rows.append(unit(y(q, lag)))
                names.append(f"y{q + 1}(k-{lag})")
    if form == "velocity":
        rows += [unit(y(q, 1)) for q in own]
        names += [f"y{q + 1}(k-1)" for q in own]
    for q in range(r):
        for lag in range(1, nb + 1):
            rows.append(unit(m * lags + q * phi_nb + lag - 1))
            names.append(f"u{q + 1}(k-{lag})")
    if affine:
        rows.append(unit(dim - 1))
        names.append("1")
    c = unit(y(j, 1)) if form == "velocity" else np.zeros(dim)
    return np.array(rows).reshape(len(rows), dim), c, names


def switching_entries(structure: str, names: list[str]) -> np.ndarray:
    """Which of ψ's entries (``names``) switch between the scheduled regions of a
    ``structure``: the constant alone (``"offset"``), none (``"continuous"``: its hinges
    carry the change) or all."""
    if structure == "offset":
        return np.array([n == "1" for n in names])
    return np.full(len(names), structure != "continuous")


@dataclass
class OutputModel:
    """The sub-models of one output (see the module doc).

    Attributes
    ----------
    M : ndarray of shape (d, D)
    c : ndarray of shape (D,)
    switching : ndarray of bool, shape (d,)
        The entries of ψ whose parameters differ between regions.
    n_regions : int
    region_of : RegionMap or None
        The map of φ rows to regions (`partitions`); None with one region.
    structure : str
        ``"linear"``, ``"offset"``, ``"all"``, ``"continuous"`` (``switching`` all
        False: the hinges' parameters come after ψ's) or ``"clustered"``.
    names : list of str
        ψ's entry names.
    p : ndarray of shape (P,)
        Shared parameters first, then each region's switching ones.
    steps : dict
        The fitted steps that found the regions (clustered: the paper's steps 2–6 on ψ),
        by name; empty otherwise.
    """

    M: Float2D
    c: np.ndarray
    switching: np.ndarray
    n_regions: int
    region_of: RegionMap | None
    structure: str
    names: list[str]
    p: np.ndarray = field(default=None)
    steps: dict = field(default_factory=dict, repr=False)

    @property
    def n_params(self) -> int:
        """P = shared entries + regions × switching entries (continuous: ψ's entries and
        one per hinge)."""
        if self.structure == "continuous":
            return self.switching.size + self.hinges().shape[0]
        n_sw = int(self.switching.sum())
        return self.switching.size - n_sw + self.n_regions * n_sw

    def size(self) -> str:
        """Its size in words for a structure's description: ``" (4 regions)"``, ``" (3
        hinges)"`` for a continuous one (whose regions may be empty), ``""`` with one
        region."""
        if self.structure == "continuous":
            v = len(self.hinges())
            return f" ({v} hinge{'s' * (v > 1)})"
        return f" ({self.n_regions} regions)" if self.n_regions > 1 else ""

    def hinges(self) -> Float2D:
        """The continuous structure's w_v over φ, shape (v, D)."""
        return self.region_of.compiled()[1]

    def G(self) -> np.ndarray:
        """M_jᵀ A_i for each region: shape (s, D, P)."""
        if self.structure == "continuous":
            w = self.hinges()
            bits = (np.arange(self.n_regions)[:, None] >> np.arange(len(w))) & 1
            linear = np.broadcast_to(self.M.T, (self.n_regions, *self.M.T.shape))
            return np.concatenate([linear, np.einsum("sv,vD->sDv", bits, w)], axis=2)
        d, sw = self.switching.size, self.switching
        n_shared, n_sw = d - int(sw.sum()), int(sw.sum())
        a = np.zeros((self.n_regions, d, self.n_params))
        a[:, np.flatnonzero(~sw), np.arange(n_shared)] = 1.0
        for i in range(self.n_regions):
            a[i, np.flatnonzero(sw), n_shared + i * n_sw + np.arange(n_sw)] = 1.0
        return np.einsum("dD,sdp->sDp", self.M, a)

    def thetas(self, p: np.ndarray | None = None) -> Float2D:
        """Θ_{j,i} = c_j + M_jᵀ A_i p over φ for each region: shape (s, D)."""
        return self.c + self.G() @ (self.p if p is None else p)

    def compiled_regions(self) -> tuple | None:
        """The region map's compiled form (`RegionMap.compiled`; one
        region: no scheduling variables), None without one."""
        if self.region_of is None:
            return "sign", np.zeros((0, self.M.shape[1])), np.zeros(0)
        return self.region_of.compiled()

    def regions(self, phi: Float2D) -> np.ndarray:
        """The region of each φ row."""
        return np.zeros(len(phi), dtype=int) if self.region_of is None \
            else self.region_of.predict(phi)

    def design(self, phi: Float2D) -> Float2D:
        """The rows φ(k)ᵀ M_jᵀ A_{λ_j(φ(k))} of the one-step prediction ŷ_j = c_jᵀφ + X p
        on φ rows (n, D): shape (n, P), the regions taken from φ."""
        g, lam = self.G(), self.regions(phi)
        x = np.zeros((len(phi), self.n_params))
        for i in range(self.n_regions):
            rows = lam == i
            x[rows] = phi[rows] @ g[i]
        return x

    def fit(self, phi: Float2D, y: np.ndarray) -> "OutputModel":
        """Least squares of ψ's sub-models on measured φ rows and the output y (n,).

        By the normal equations of the design with its columns scaled to unit RMS, solved
        for the minimum-norm solution (directions whose singular value is below
        √(ε·P) of the largest are dropped): a fifth of the time of a factorisation of the
        tall design, for the structure search's thousand-odd candidate fits. A region no
        row falls in keeps zero switching parameters."""
        x = self.design(phi)
        scale = np.sqrt(np.mean(x * x, axis=0))
        scale[scale == 0] = 1.0
        x /= scale
        gram, moment = x.T @ x, x.T @ (y - phi @ self.c)
        self.p = np.linalg.lstsq(gram, moment, rcond=None)[0] / scale
        return self


def assign_params(models: dict[int, "OutputModel"], group: list[int], p: np.ndarray) -> None:
    """Give each output j of ``group`` its p_j out of their concatenation ``p`` (the order
    of `refine_outputs`' parameters)."""
    offsets = np.cumsum([0] + [models[j].n_params for j in group])
    for jj, j in enumerate(group):
        models[j].p = p[offsets[jj]:offsets[jj + 1]]


def output_groups(outputs: list[OutputModel], limits: np.ndarray | None = None
                  ) -> list[OutputGroup]:
    """The fitted shape of a structured model (`groups`): each output's rows
    Θ_{j,i} over φ, outputs with the same region map in one group, with their ``limits``
    (2, m; `limits`)."""
    regions = [SingleRegion(o.M.shape[1]) if o.region_of is None else o.region_of
               for o in outputs]
    return grouped(regions, [o.thetas() for o in outputs], [o.steps for o in outputs],
                   limits)
