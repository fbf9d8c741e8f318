"""Regressor vectors φ(k) of a MIMO ARX structure (paper eq. 2–3)."""

from dataclasses import dataclass

import numpy as np

from ._typing import Float2D


@dataclass(frozen=True)
class Regressors:
    """Regressors and targets stacked over experiments.

    Attributes
    ----------
    phi : ndarray of shape (n, d)
        φ(k) per row, in the order of eq. (2)–(3).
    target : ndarray of shape (n, m)
        y(k) per row.
    experiment : ndarray of shape (n,)
        Index of the experiment each row comes from.
    time : ndarray of shape (n,)
        Sample index k of each row inside its experiment.
    n_inputs : int
        r, the number of input channels (φ alone does not tell it when nb = 0).
    """

    phi: Float2D
    target: Float2D
    experiment: np.ndarray
    time: np.ndarray
    n_inputs: int

    @property
    def n_outputs(self) -> int:
        """m, the number of output channels."""
        return self.target.shape[1]

    def subset(self, rows: np.ndarray) -> "Regressors":
        """The rows selected by a boolean or index array."""
        return Regressors(phi=self.phi[rows], target=self.target[rows],
                          experiment=self.experiment[rows], time=self.time[rows],
                          n_inputs=self.n_inputs)


def n_initial(na: int, nb: int) -> int:
    """Number of leading samples that have no complete regressor: max(na, nb)."""
    return max(na, nb)


def regressor_dim(m: int, r: int, na: int, nb: int, affine: bool) -> int:
    """Regressor length d = m·na + r·nb (+1 with the affine term), eq. (2)–(4)."""
    return m * na + r * nb + int(affine)


def regressor_names(
    y_names: list[str], u_names: list[str], na: int, nb: int, affine: bool
) -> list[str]:
    """Human-readable names of φ's entries, e.g. ``y1(k-1)``, in eq. (3) order."""
    names = [f"{n}(k-{j})" for n in y_names for j in range(1, na + 1)]
    names += [f"{n}(k-{j})" for n in u_names for j in range(1, nb + 1)]
    return names + (["1"] if affine else [])


def lagged_matrix(u: Float2D, y: Float2D, na: int, nb: int, affine: bool) -> Float2D:
    """φ(k) for k = max(na, nb), …, N−1 of one experiment, one row each (eq. 2–3).

    Per output all its lags y_(p)(k−1) … y_(p)(k−na), then per input all its lags
    u_(q)(k−1) … u_(q)(k−nb), then 1 when ``affine``.
    """
    n0, n = n_initial(na, nb), y.shape[0]
    cols = [y[n0 - j : n - j, p] for p in range(y.shape[1]) for j in range(1, na + 1)]
    cols += [u[n0 - j : n - j, q] for q in range(u.shape[1]) for j in range(1, nb + 1)]
    if affine:
        cols.append(np.ones(n - n0))
    return np.column_stack(cols) if cols else np.empty((n - n0, 0))


def build_regressors(
    experiments: list[tuple[Float2D, Float2D]], na: int, nb: int, affine: bool
) -> Regressors:
    """Stack φ(k) and y(k) over experiments without letting a lag span two of them.

    Parameters
    ----------
    experiments : list of (u, y)
        As returned by `pwa_pipeline._validation.as_experiments`.
    na, nb : int
        Output and input orders of eq. (3).
    affine : bool
        Append the constant 1 of eq. (2).

    Raises
    ------
    ValueError
        If the orders are negative, both zero, or no experiment is longer than max(na, nb).
    """
    if na < 0 or nb < 0 or na + nb == 0:
        raise ValueError(f"orders must satisfy na >= 0, nb >= 0, na + nb >= 1; got {na}, {nb}")
    n0 = n_initial(na, nb)
    phis, targets, exp_idx, times = [], [], [], []
    for e, (u, y) in enumerate(experiments):
        if y.shape[0] <= n0:
            continue
        phis.append(lagged_matrix(u, y, na, nb, affine))
        targets.append(y[n0:])
        exp_idx.append(np.full(y.shape[0] - n0, e))
        times.append(np.arange(n0, y.shape[0]))
    if not phis:
        lengths = [y.shape[0] for _, y in experiments]
        raise ValueError(
            f"no experiment is longer than max(na, nb) = {n0} samples (lengths {lengths})"
        )
    return Regressors(
        phi=np.vstack(phis),
        target=np.vstack(targets),
        experiment=np.concatenate(exp_idx),
        time=np.concatenate(times),
        n_inputs=experiments[0][0].shape[1],
    )
