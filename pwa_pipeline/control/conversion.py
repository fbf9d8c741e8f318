"""From a fitted PWARX or LinearARX model to its PWA state-space form
([`PWAStateSpace`][pwa_pipeline.control.PWAStateSpace]).

**Dynamics.** Every model of the project predicts y(k) from the regressor φ(k) of eq. (2)–(3)
(L output lags, nb input lags, the constant when affine; L = na + 1 in the velocity form,
whose increments are linear in φ): output p by a parameter row Θ_{p,i} over φ chosen by its
region i (eq. 1). With the state x(k) = φ(k) without the constant, a mode's C_i and g_i are
those rows over x and over the constant, and A_i, B_i, f_i shift the lags
(`mode_matrices`). Output lags that no parameter row or region reads (a structure search's
φ holds na + 1 of them, its level-form choice of order na reads na) are left out of the
state (`used_lags`): the state holds no entry that nothing reads.

**Regions.** The fitted model keeps its outputs in groups, each with one region map over φ
(``model.groups_``, `pwa_pipeline.pwa.groups`) whose ``halfspaces()`` write each
region as {φ : G φ ≤ q} (`pwa_pipeline.pwa.partitions`: the argmax of the SVM regions,
the signs of scheduling variables, a map over an output group's regressor ψ = Mφ, one
region). φ = [x; 1] (or x) is linear in z = [x; u], so each region is an H-polyhedron over
z. With one group (the paper's route, a linear model) the modes are its regions; with several
the PWA system's modes are the cells of the product partition, ordered lexicographically
(the first group's region varies slowest), only those non-empty inside the envelope kept.

**Envelope.** Each region is intersected with the data envelope: the box whose every entry
spans its channel's training range (the smallest and largest value of that output or input
over the training experiments; all lags of a channel share it), widened on each side by
``padding`` (default 5 %) of that span (of the channel's magnitude, at least 1, when the span
is zero): over x, the box the fitted model's own
`outside_envelope` tests φ against
(`pwa_pipeline.envelope`, the one place it is computed), and over u(k) the inputs'
padded ranges. A cell whose Chebyshev ball inside the envelope has radius at most
`EMPTY_RADIUS` half-widths is dropped and listed in ``dropped_modes``;
redundant rows are removed by linear programs (`irredundant_rows`).

**Limits.** A model whose outputs have limits (``output_limits_``,
`pwa_pipeline.pwa.limits`) splits each cell further by the hyperplanes Θ_{p,i}ᵀφ = lo_p,
hi_p of each limited output p: the part within the limits keeps the sub-model, the parts
past one hold ŷ_p at it (a zero row of C_i and of the state's lag-1 entry of p, g_p and f at
the limit; `PWAStateSpace.held`), each kept when non-empty inside the envelope, with the
cell's ``mode_regions``.

**Ties.** The closed regions overlap on their boundaries. The modes keep the fitted model's
order (its region index, lexicographically over partitions), so the rule "the
lowest-numbered region that holds z" ([`PWAStateSpace.mode_of`][pwa_pipeline.control.PWAStateSpace.mode_of])
is the model's own: an argmax picks the lowest index among equal scores, a sign test puts 0 with bit 0, and
the lowest product cell is the product of the lowest regions.
"""

import itertools
from dataclasses import dataclass

import numpy as np
from sklearn.utils.validation import check_is_fitted

from .._typing import Float2D, Signals
from .._validation import as_experiments
from ..envelope import PADDING, channel_bounds, regressor_bounds, training_range
from .polyhedra import EMPTY_RADIUS, Box, chebyshev_ball, irredundant_rows
from .state_space import PWAStateSpace


@dataclass
class Partition:
    """One output group's partition of φ-space into closed regions {φ : G φ ≤ q}.

    Attributes
    ----------
    labels : ndarray of int, shape (s,)
        The fitted model's index of each region (those that are ever chosen).
    rows : list of (ndarray of shape (k, D), ndarray of shape (k,))
        (G, q) of each region, over φ.
    outputs : tuple of int
        The outputs whose sub-model it chooses.
    """

    labels: np.ndarray
    rows: list[tuple[Float2D, np.ndarray]]
    outputs: tuple[int, ...]


def partition(group) -> Partition:
    """The `Partition` of a fitted output group (its region map's ``halfspaces()``,
    the regions never chosen left out)."""
    cells = group.regions.halfspaces()
    live = [i for i, cell in enumerate(cells) if cell is not None]
    return Partition(np.array(live), [cells[i] for i in live], tuple(group.outputs))


def mode_matrices(theta: Float2D, m: int, r: int, lags: int, nb: int, affine: bool
                  ) -> tuple[Float2D, Float2D, np.ndarray, Float2D, np.ndarray]:
    """A, B, f, C, g of one mode from its parameter matrix Θ (D, m) over φ.

    y(k) = Θᵀφ(k) = C x(k) + g with C = Θ[:n]ᵀ and g = Θ[n] (0 without the constant); the
    state update puts y(k) in each output's lag-1 entry and u(k) in each input's, and moves
    every other lag one place on.
    """
    n = m * lags + r * nb
    C = theta[:n].T.copy()
    g = theta[n].copy() if affine else np.zeros(m)
    A, B, f = np.zeros((n, n)), np.zeros((n, r)), np.zeros(n)
    for p in range(m):
        first = p * lags
        if lags:
            A[first] = C[p]
            f[first] = g[p]
        for lag in range(1, lags):
            A[first + lag, first + lag - 1] = 1.0
    for q in range(r):
        first = m * lags + q * nb
        if nb:
            B[first, q] = 1.0
        for lag in range(1, nb):
            A[first + lag, first + lag - 1] = 1.0
    return A, B, f, C, g


def envelope_box(signal_range: Float2D, m: int, r: int, lags: int, nb: int,
                 padding: float) -> Box:
    """The data envelope over z = [x; u] from each channel's training range: over x the
    box of `regressor_bounds` (φ without the constant),
    over u(k) each input's `channel_bounds`.

    Parameters
    ----------
    signal_range : ndarray of shape (2, m + r)
        Smallest and largest value of each output, then each input.
    padding : float
        Share of each span added on either side (of max(|min|, |max|, 1) for a constant
        channel).
    """
    x_lo, x_hi = regressor_bounds(signal_range, m, r, lags, nb, padding)
    lo, hi = channel_bounds(signal_range, padding)
    return Box(np.concatenate([x_lo, lo[m:]]), np.concatenate([x_hi, hi[m:]]))


def signal_range(u: Signals, y: Signals) -> Float2D:
    """Smallest and largest value of each output, then each input, over the experiments:
    shape (2, m + r) (`training_range`)."""
    return training_range(as_experiments(u, y))


def _to_z(G: Float2D, q: np.ndarray, n: int, r: int, affine: bool
          ) -> tuple[Float2D, np.ndarray]:
    """Rows G φ ≤ q over φ = [x; 1] (or x) as rows over z = [x; u]."""
    Gz = np.hstack([G[:, :n], np.zeros((G.shape[0], r))])
    return Gz, (q - G[:, n]) if affine else q.astype(float)


def to_state_space(model, u: Signals | None = None, y: Signals | None = None, *,
                   padding: float = PADDING, input_names: list[str] | None = None,
                   output_names: list[str] | None = None) -> PWAStateSpace:
    """The PWA state-space form of a fitted PWARX or LinearARX model (see the module doc).

    Parameters
    ----------
    model : fitted PWARX or LinearARX
        Any fitted model with output groups (``groups_``) over the regressor of eq. (2)–(3)
        (``output_lags_``, ``nb``, ``affine``, ``n_outputs_``, ``n_inputs_``).
    u, y : array-like or lists of them, optional
        Data whose range makes the envelope (the training data). None: the model's
        ``signal_range_``, the range of its training data recorded at fit.
    padding : float, default PADDING (0.05)
        Widening of the envelope beyond that range, a share of each channel's span.
    input_names, output_names : list of str, optional
        Names for the state's entries (default ``u1…``, ``y1…``).

    Returns
    -------
    PWAStateSpace

    Raises
    ------
    ValueError
        If neither data nor ``signal_range_`` give the envelope, ``padding`` is not positive,
        or every region is empty inside the envelope.

    Examples
    --------
    >>> import numpy as np
    >>> from pwa_pipeline import LinearARX
    >>> u = np.random.default_rng(0).normal(size=(300, 1))
    >>> y = np.zeros((300, 1))
    >>> for k in range(1, 300):
    ...     y[k] = 0.5 * y[k - 1] + u[k - 1]
    >>> model = LinearARX(na=1, nb=1).fit(u, y)
    >>> ss = to_state_space(model)
    >>> ss.n_modes, ss.state_names
    (1, ['y1(k-1)', 'u1(k-1)'])
    >>> bool(np.allclose(ss.simulate(u, y[:1]), model.simulate(u, y[:1]), rtol=0, atol=1e-8))
    True
    """
    check_is_fitted(model)
    m, r = model.n_outputs_, model.n_inputs_
    nb, affine = model.nb, model.affine
    groups = list(model.groups_)
    distinct = [partition(group) for group in groups]
    lags, columns = used_lags(model.output_lags_, m, r, nb, groups, distinct)
    n = m * lags + r * nb
    if not (isinstance(padding, int | float) and np.isfinite(padding) and padding > 0):
        raise ValueError(f"padding must be a positive share of each span, got {padding!r}")
    if (u is None) != (y is None):
        raise ValueError("give both u and y (the training data) or neither")
    if u is not None:
        rng = signal_range(u, y)
        if rng.shape[1] != m + r:
            raise ValueError(f"the data have {rng.shape[1]} channels; the model has {m} "
                             f"output(s) and {r} input(s)")
    elif getattr(model, "signal_range_", None) is not None:
        rng = np.asarray(model.signal_range_, dtype=float)
    else:
        raise ValueError(
            "the model does not record the range of its training data (it was fitted "
            "before signal_range_ existed): pass the training data, to_state_space(u, y)")
    box = envelope_box(rng, m, r, lags, nb, padding)
    p_dim = n + r
    box_H, box_h = box.rows()

    part_of = [0] * m
    for k, group in enumerate(groups):
        for p in group.outputs:
            part_of[p] = k
    zrows = [[_to_z(G[:, columns], q, n, r, affine) for G, q in part.rows]
             for part in distinct]

    def ball(G: Float2D, q: np.ndarray) -> tuple[float, np.ndarray | None]:
        return chebyshev_ball(*box.to_unit(np.vstack([G, box_H]), np.concatenate([q, box_h])))

    # the product cells non-empty inside the envelope, partition by partition, each with the
    # centre of its Chebyshev ball (in the box's coordinates)
    cells = [((), np.zeros((0, p_dim)), np.zeros(0), None)]
    dropped_prefixes = []
    for k, part_rows in enumerate(zrows):
        grown = []
        for index, G, q, centre in cells:
            for j, (Gj, qj) in enumerate(part_rows):
                G2, q2 = np.vstack([G, Gj]), np.concatenate([q, qj])
                if len(part_rows) == 1 and k > 0:  # one region adds no condition
                    grown.append((index + (j,), G2, q2, centre))
                    continue
                radius, centre2 = ball(G2, q2)
                if radius > EMPTY_RADIUS:
                    grown.append((index + (j,), G2, q2, centre2))
                else:
                    dropped_prefixes.append(index + (j,))
        cells = grown
    if not cells:
        raise ValueError("every region of the model is empty inside the data envelope "
                         "(check the envelope's data and the regions)")

    def labels_of(index: tuple) -> list[int]:
        return [int(distinct[part_of[p]].labels[index[part_of[p]]]) for p in range(m)]

    dropped = []
    for prefix in dropped_prefixes:
        rest = [range(len(rows)) for rows in zrows[len(prefix):]]
        dropped += [labels_of(prefix + tail) for tail in itertools.product(*rest)]

    limits = getattr(model, "output_limits_", None)
    mats = {name: [] for name in "ABfCg"}
    regions, mode_regions = [], []
    for index, G0, q0, centre0 in cells:
        labels = labels_of(index)
        theta = np.empty((n + int(affine), m))
        for group in groups:
            theta[:, group.outputs] = group.thetas[labels[group.outputs[0]]][columns]
        for G, q, centre, held in _limited_parts(theta, limits, G0, q0, centre0, n, r,
                                                 affine, ball):
            for name, value in zip("ABfCg", _held(mode_matrices(theta, m, r, lags, nb,
                                                                affine), held, lags),
                                   strict=True):
                mats[name].append(value)
            regions.append(_irredundant(box, box_H, box_h, G, q, centre))
            mode_regions.append(labels)
    ss = PWAStateSpace(
        np.array(mats["A"]), np.array(mats["B"]), np.array(mats["f"]), np.array(mats["C"]),
        np.array(mats["g"]), regions, box.lower, box.upper, output_lags=lags, input_lags=nb,
        affine=affine, input_names=input_names, output_names=output_names, padding=padding,
        mode_regions=mode_regions, dropped_modes=np.array(dropped, dtype=int).reshape(-1, m),
        source=model_source(model))
    check_regions(ss, groups, columns, model.output_lags_)
    return ss


def _irredundant(box: Box, box_H: Float2D, box_h: np.ndarray, G: Float2D, q: np.ndarray,
                 centre: np.ndarray | None) -> tuple[Float2D, np.ndarray]:
    """A mode's region {z : G z ≤ q} inside the envelope ``box``, without redundant rows."""
    Ht, ht = box.to_unit(np.vstack([G, box_H]), np.concatenate([q, box_h]))
    # a box row of a coordinate no other row involves always shapes the region
    touched = np.any(G != 0, axis=0)
    protected = np.concatenate([np.zeros(len(q), bool), ~touched, ~touched])
    keep = irredundant_rows(Ht, ht, protected, interior=centre)
    return box.from_unit(Ht[keep], ht[keep])


def _limited_parts(theta: Float2D, limits: Float2D | None, G: Float2D, q: np.ndarray,
                   centre: np.ndarray | None, n: int, r: int, affine: bool, ball):
    """The parts of one cell {z : G z ≤ q} that the outputs' limits (`pwa_pipeline.pwa.limits`)
    make: for each output p with a limit, the part where Θ_pᵀφ lies within its limits and
    those where it is past one (ŷ_p held there), each non-empty inside the envelope.

    Returns
    -------
    list of (G, q, centre, held)
        ``held`` maps each output held at a limit in that part to the limit.
    """
    parts = [(G, q, centre, {})]
    if limits is None:
        return parts
    for p in np.flatnonzero(np.any(np.isfinite(limits), axis=0)):
        lo, hi = limits[:, p]
        t = theta[:, p][None, :]
        inside = [(row, bound) for row, bound in ((t, hi), (-t, -lo)) if np.isfinite(bound)]
        pieces = [(inside, None)]
        pieces += [([(-t, -hi)], hi)] if np.isfinite(hi) else []
        pieces += [([(t, lo)], lo)] if np.isfinite(lo) else []
        grown = []
        for Gc, qc, _, held in parts:
            for rows, level in pieces:
                Gz, qz = _to_z(np.vstack([row for row, _ in rows]),
                               np.array([bound for _, bound in rows], dtype=float), n, r,
                               affine)
                G2, q2 = np.vstack([Gc, Gz]), np.concatenate([qc, qz])
                radius, centre2 = ball(G2, q2)
                if radius > EMPTY_RADIUS:
                    grown.append((G2, q2, centre2,
                                  held if level is None else {**held, int(p): level}))
        parts = grown
    return parts


def _held(matrices: tuple, held: dict, lags: int) -> tuple:
    """A mode's A, B, f, C, g with each output p of ``held`` constant at its limit:
    ŷ_p = held[p], which the state's lag-1 entry of p takes on."""
    A, B, f, C, g = (x.copy() for x in matrices)
    for p, level in held.items():
        C[p], g[p] = 0.0, level
        if lags:
            A[p * lags], f[p * lags] = 0.0, level
    return A, B, f, C, g


def used_lags(lags: int, m: int, r: int, nb: int, groups, partitions: list[Partition]
              ) -> tuple[int, np.ndarray]:
    """The output lags the state keeps, and the columns of φ they and the rest take.

    A regressor of more output lags than the model uses (a structure search's φ holds
    na + 1 lags for its velocity-form candidates; a level-form choice of order na leaves
    the last lag unused) would give states that no output, region or other state reads:
    the lags from the last one any sub-model's parameter row or any region's inequality
    reads (at least one) are left out of the state, so that its simulation is the model's
    from the same warm-up.

    Returns
    -------
    used : int
        Output lags kept, 1 ≤ used ≤ `lags`.
    columns : ndarray of int
        The columns of φ (the constant last, if any) the state-space model is built on.
    """
    d = m * lags + r * nb
    read = np.zeros(d, bool)
    for group in groups:
        read |= np.any(np.asarray(group.thetas)[:, :d] != 0, axis=(0, 2))
    for part in partitions:
        for G, _ in part.rows:
            read |= np.any(np.asarray(G)[:, :d] != 0, axis=0)
    by_lag = read[:m * lags].reshape(m, lags).any(axis=0) if lags else np.zeros(0, bool)
    used = max(1, int(np.flatnonzero(by_lag).max()) + 1) if by_lag.any() else min(lags, 1)
    kept = [p * lags + j for p in range(m) for j in range(used)]
    total = groups[0].thetas.shape[1]
    return used, np.array([*kept, *range(m * lags, total)], dtype=int)


def model_source(model) -> dict:
    """What an export was converted from, for the record: the class, orders and constant,
    each output's structure in words (form, orders, regions, as `model.structures_`
    says: the structure search's choice, not the estimator's defaults) and whether the
    outputs share one model (`joint`) or form several output groups."""
    groups = list(model.groups_)
    return {"model": type(model).__name__, "na": model.na, "nb": model.nb,
            "affine": model.affine, "structures": list(model.structures_),
            "outputs": "joint" if len(groups) == 1 else
            f"{len(groups)} output groups: "
            + "; ".join(", ".join(f"y{j + 1}" for j in g.outputs) for g in groups)}


#: Random points of the envelope at which `check_regions` compares the exported
#: regions with the model's own.
CHECK_POINTS = 2000


def check_regions(ss: PWAStateSpace, groups, columns: np.ndarray, lags: int) -> None:
    """Raise ValueError where the exported regions disagree with the output groups' own
    ``predict`` at `CHECK_POINTS` seeded random points of the envelope: a region map
    whose ``halfspaces()`` do not describe the regions its ``predict()`` gives (a region
    step of one's own that overrides one and not the other) would otherwise export another
    model than the fitted one. `columns` (`used_lags`) place the state in the model's
    φ of `lags` output lags, the lags the state leaves out at 0."""
    rng = np.random.default_rng(0)
    lower, upper = ss.envelope
    z = lower + rng.random((CHECK_POINTS, lower.size)) * (upper - lower)
    x = z[:, :ss.n_states]
    full = np.zeros((len(z), ss.n_outputs * lags + ss.n_inputs * ss.input_lags))
    full[:, columns[:ss.n_states]] = x
    phi = np.column_stack([full, np.ones(len(z))]) if ss.affine else full
    exported = ss.mode_regions[ss.mode_of(x, z[:, ss.n_states:])]
    for group in groups:
        wrong = int(np.sum(group.regions.predict(phi) != exported[:, group.outputs[0]]))
        if wrong:
            raise ValueError(
                f"to_state_space: the halfspaces() of {type(group.regions).__name__} (outputs "
                f"{', '.join(f'y{j + 1}' for j in group.outputs)}) do not describe the regions "
                f"its predict() gives: they disagree at {wrong} of {CHECK_POINTS} random "
                f"points of the data envelope")
