"""The free run of an ARX-structured model and its sensitivities dŷ(k)/dθ, for the
output-error refinement (`pwa_pipeline.pwa.output_error`).

The Jacobian of the free run is propagated forward in time (sensitivities through the output
lags of φ̂, the region treated as locally constant), for all experiments at once, and only
JᵀJ (P × P) and Jᵀr are kept, never J itself (N·m × P rows).
"""

from collections.abc import Callable

import numpy as np

from ..._typing import Float2D
from ..kernels.free_run import pack_regions
from ..kernels.sensitivities import sensitivity_block

#: Time steps the compiled free run runs between two products of its Jacobian rows.
BLOCK = 2048


class _NormalEquations:
    """JᵀJ and Jᵀr of the free run, from Jacobian rows gathered over 32 time steps for one
    larger product."""

    def __init__(self, p: int):
        self.jtj, self.jtr = np.zeros((p, p)), np.zeros(p)
        self._rows: list[np.ndarray] = []
        self._res: list[np.ndarray] = []

    def add(self, rows: np.ndarray, residuals: np.ndarray, last: bool) -> None:
        """Add the rows dŷ/dθ (n, p) and residuals (n,) of one time step."""
        self._rows.append(rows)
        self._res.append(residuals)
        if len(self._rows) == 32 or last:
            rows_j, res = np.vstack(self._rows), np.concatenate(self._res)
            self.jtj += rows_j.T @ rows_j
            self.jtr += rows_j.T @ res
            self._rows, self._res = [], []


class FreeRuns:
    """The training experiments padded to one length, simulated in lockstep.

    ``simulated`` (default: every output) are the outputs that run free; the others keep
    their measured values (with decoupled per-output models they do not enter the
    simulated ones). ``limits`` (2, m; `pwa_pipeline.pwa.limits`) clip every simulated
    output, whose sensitivities are 0 while it sits at a limit.
    """

    def __init__(self, u: list[Float2D], y: list[Float2D], na: int, nb: int, affine: bool,
                 warmup: int, simulated: list[int] | None = None,
                 limits: Float2D | None = None):
        self.na, self.nb, self.affine, self.warmup = na, nb, affine, warmup
        self.lengths = np.array([len(e) for e in y])
        n, e = self.lengths.max(), len(y)
        self.u = np.zeros((e, n, u[0].shape[1]))
        self.y = np.zeros((e, n, y[0].shape[1]))
        for i, (ue, ye) in enumerate(zip(u, y, strict=True)):
            self.u[i, :len(ue)], self.y[i, :len(ye)] = ue, ye
        self.simulated = list(range(self.y.shape[2]) if simulated is None else simulated)
        m = self.y.shape[2]
        self.lower, self.upper = (np.full(m, -np.inf), np.full(m, np.inf)) \
            if limits is None else (np.asarray(limits[0], float), np.asarray(limits[1], float))
        self.n_scored = int(np.maximum(self.lengths - warmup, 0).sum()) * len(self.simulated)

    def phi(self, ysim: np.ndarray, k: int) -> Float2D:
        """φ̂(k) of every experiment, in eq. (3)'s order, from the simulated outputs."""
        e = ysim.shape[0]
        ylags = ysim[:, k - self.na:k][:, ::-1].transpose(0, 2, 1).reshape(e, -1)
        ulags = self.u[:, k - self.nb:k][:, ::-1].transpose(0, 2, 1).reshape(e, -1)
        parts = [ylags, ulags] + ([np.ones((e, 1))] if self.affine else [])
        return np.concatenate(parts, axis=1)

    def simulate(self, thetas: np.ndarray, region_of: Callable | None,
                 sensitivities: bool) -> tuple[float, np.ndarray | None, np.ndarray | None]:
        """Cost J / (scored samples · outputs), and JᵀJ and Jᵀr when ``sensitivities``, of
        parameter matrices θ (s, d, m) flattened as (region, regressor, output).

        Returns inf (and no normal equations) when the run leaves the finite numbers.
        """
        s, d, m = thetas.shape
        rows, outs = np.arange(self.y.shape[0])[:, None, None], np.arange(m)[None, :, None]

        def step(phi):
            region = np.zeros(len(phi), dtype=int) if region_of is None else region_of(phi)

            def direct(sk):  # dŷ_j(k)/dθ_{λ(k), a, j} = φ_a(k)
                cols = region[:, None, None] * d * m + np.arange(d)[None, None, :] * m + outs
                sk[rows, outs, cols] = phi[:, None, :]

            return thetas[region], direct

        with np.errstate(over="ignore", invalid="ignore"):
            return self._run(step, s * d * m, sensitivities)

    def _run(self, step: Callable, n_params: int, sensitivities: bool):
        """The free run and its sensitivities dŷ(k)/dθ, propagated through the output lags
        of φ̂. ``step(φ̂)`` gives every experiment's parameter matrix at k, (e, d, outputs
        simulated), and a function adding the direct term dŷ(k)/dθ at fixed φ̂ to an
        (e, outputs simulated, n_params) array."""
        e, n = self.y.shape[:2]
        sim, w, na = self.simulated, self.warmup, self.na
        ysim = self.y.copy()
        lag_rows = [[q * na + lag - 1 for q in sim] for lag in range(1, na + 1)]
        sens = np.zeros((na + 1, e, len(sim), n_params))  # ring buffer of dŷ(k)/dθ
        normal, cost = _NormalEquations(n_params), 0.0
        for k in range(w, n):
            active = self.lengths > k
            phi = self.phi(ysim, k)
            theta_k, direct = step(phi)
            raw = np.einsum("ed,edj->ej", phi, theta_k)
            yk = np.clip(raw, self.lower[sim], self.upper[sim])
            target = self.y[:, k][:, sim]
            ysim[:, k, sim] = np.where(active[:, None], yk, target)
            r = np.where(active[:, None], yk - target, 0.0)
            cost += float(np.sum(r * r))
            if not np.isfinite(cost):
                return np.inf, None, None
            if not sensitivities:
                continue
            sk = np.zeros((e, len(sim), n_params))
            direct(sk)
            # through the output lags of φ̂: φ_{q, lag}(k) = ŷ_q(k − lag)
            for lag in range(1, min(na, k - w) + 1):
                a = theta_k[:, lag_rows[lag - 1], :]                   # (e, q, j)
                sk += np.einsum("eqj,eqp->ejp", a, sens[(k - lag) % (na + 1)])
            sk[~active] = 0.0
            sk[yk != raw] = 0.0  # held at a limit
            sens[k % (na + 1)] = sk
            normal.add(sk.reshape(-1, n_params), r.ravel(), last=k == n - 1)
        if not sensitivities:
            return cost / self.n_scored, None, None
        return cost / self.n_scored, normal.jtj, normal.jtr


class OutputFreeRuns(FreeRuns):
    """The experiments simulated with per-output models
    (`OutputModel`): the outputs ``simulated`` run free, the others
    keep their measured values.

    The parameters are the concatenated p_j of the simulated outputs.
    """

    def __init__(self, u, y, lags: int, nb: int, affine: bool, warmup: int,
                 models: list, simulated: list[int], limits: Float2D | None = None):
        super().__init__(u, y, lags, nb, affine, warmup, simulated, limits)
        self.models = models
        self.g = [models[j].G() for j in self.simulated]
        self.offsets = np.cumsum([0] + [g.shape[2] for g in self.g])
        forms = [models[j].compiled_regions() for j in self.simulated]
        #: The compiled kernel's fixed arrays (dθ/dp and the regions), built once: the
        #: regions stay fixed while p is refined; None where the numpy loop runs.
        self.kernel = self._kernel_arrays(forms) \
            if affine and all(f is not None for f in forms) else None

    def simulate(self, p: np.ndarray, sensitivities: bool):
        """As `FreeRuns.simulate`, with the concatenated p_j: compiled
        (`sensitivities`) for models on an affine φ whose
        regions have a compiled form (linear, sign-scheduled, clustered), else the numpy
        loop."""
        sim, bounds = self.simulated, list(zip(self.offsets[:-1], self.offsets[1:]))
        thetas = [self.models[j].c + g @ p[a:b]
                  for j, g, (a, b) in zip(sim, self.g, bounds, strict=True)]
        if self.kernel is not None:
            return self._compiled(thetas, sensitivities)
        return self._looped(thetas, sensitivities)

    def _looped(self, thetas: list[np.ndarray], sensitivities: bool):
        """`simulate` by the numpy loop, for any region maps."""
        sim, bounds = self.simulated, list(zip(self.offsets[:-1], self.offsets[1:]))

        def step(phi):
            regions = [self.models[j].regions(phi) for j in sim]

            def direct(sk):
                for jj, (g, reg, (a, b)) in enumerate(zip(self.g, regions, bounds)):
                    sk[:, jj, a:b] = np.einsum("ed,edp->ep", phi, g[reg])

            return np.stack([t[r] for t, r in zip(thetas, regions, strict=True)], axis=2), direct

        with np.errstate(over="ignore", invalid="ignore"):
            return self._run(step, int(self.offsets[-1]), sensitivities)

    def _kernel_arrays(self, forms: list) -> tuple:
        """The compiled kernel's arguments that do not change with p: the simulated
        outputs, dθ/dp per output and region (each output's columns between its offsets),
        the offsets and the regions (``forms``: the simulated outputs' compiled regions)."""
        n_par, d = int(self.offsets[-1]), self.g[0].shape[1]
        gmat = np.zeros((len(self.g), max(len(g) for g in self.g), d, n_par))
        for jj, g in enumerate(self.g):
            gmat[jj, :len(g), :, self.offsets[jj]:self.offsets[jj + 1]] = g
        return (np.array(self.simulated, dtype=np.int64), gmat,
                self.offsets.astype(np.int64), *pack_regions(forms, d))

    def _compiled(self, thetas: list[np.ndarray], sensitivities: bool):
        """`simulate` by the compiled kernel, a block of `BLOCK` time steps at a time,
        JᵀJ and Jᵀr summed by one matrix product per block."""
        sim, n_par = self.simulated, int(self.offsets[-1])
        n_exp, n = self.y.shape[:2]
        outputs, gmat, offsets, *regions = self.kernel
        packed = np.zeros(gmat.shape[:3])
        for jj, t in enumerate(thetas):
            packed[jj, :len(t)] = t
        lengths = self.lengths.astype(np.int64)
        ysim, ring = self.y.copy(), np.zeros((n_exp, self.na + 1, len(sim), n_par))
        rows = np.empty((BLOCK * n_exp * len(sim), n_par) if sensitivities else (0, n_par))
        residuals = np.empty(len(rows))
        jtj, jtr, cost = np.zeros((n_par, n_par)), np.zeros(n_par), 0.0
        for k0 in range(self.warmup, n, BLOCK):
            k1 = min(n, k0 + BLOCK)
            cost += sensitivity_block(self.y, self.u, lengths, self.warmup, self.na, self.nb,
                                      outputs, packed, gmat, offsets, *regions,
                                      self.lower, self.upper, k0, k1,
                                      ysim, ring, rows, residuals, sensitivities)
            if not np.isfinite(cost):
                return np.inf, None, None
            if sensitivities:
                used = (k1 - k0) * n_exp * len(sim)
                jtj += rows[:used].T @ rows[:used]
                jtr += rows[:used].T @ residuals[:used]
        if not sensitivities:
            return cost / self.n_scored, None, None
        return cost / self.n_scored, jtj, jtr
