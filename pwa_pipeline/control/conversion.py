"""From a fitted PWARX or LinearARX model to its PWA state-space form (:class:`PWAStateSpace`).

**Dynamics.** Every model of the project predicts y(k) from the regressor φ(k) of eq. (2)–(3)
(L output lags, nb input lags, the constant when affine; L = na + 1 in the velocity form,
whose increments are linear in φ): output p by a parameter row Θ_{p,i} over φ chosen by its
region i (eq. 1). With the state x(k) = φ(k) without the constant, a mode's C_i and g_i are
those rows over x and over the constant, and A_i, B_i, f_i shift the lags
(:func:`mode_matrices`).

**Regions.** Each output's regions are a partition of φ-space given by the fitted model:

- the multi-class SVM of step 6 and the default's gate (:class:`~pwa_pipeline.pwa.steps.regions.
  SVMRegions`, :class:`~pwa_pipeline.pwa.steps.boundaries.ResidualRegions`): φ ∈ H_i ⇔
  i = argmax_j (w_j·φ + b_j), so H_i = {φ : (w_j − w_i)·φ ≤ b_i − b_j for every j ≠ i}
  (regions whose b_i is −inf are never chosen and have no row);
- the same on an output group's regressor ψ = Mφ (structured route): w_j·Mφ;
- the signs of scheduling variables w_vᵀφ (:class:`~pwa_pipeline.pwa.scheduling.
  SignRegions`): bit v is 1 where w_vᵀφ > 0, so the region of bits β is
  {φ : w_vᵀφ ≤ 0 where β_v = 0, −w_vᵀφ ≤ 0 where β_v = 1};
- one region (a linear model).

φ = [x; 1] (or x) is linear in z = [x; u], so each region is an H-polyhedron over z. Outputs
with the same partition (all of them on the joint clustered routes) share it; otherwise
(decoupled outputs, scheduling on each output's own increment) the PWA system's modes are the
cells of the product partition, ordered lexicographically (the first output's region varies
slowest), only those non-empty inside the envelope kept.

**Envelope.** Each region is intersected with the data envelope: the box whose every entry
spans its channel's training range (the smallest and largest value of that output or input
over the training experiments; all lags of a channel share it), widened on each side by
``padding`` (default 5 %) of that span (of the channel's magnitude, at least 1, when the span
is zero): over x, the box the fitted model's own
:meth:`~pwa_pipeline.pwa.arx.ARXModelBase.outside_envelope` tests φ against
(:mod:`pwa_pipeline.envelope`, the one place it is computed), and over u(k) the inputs'
padded ranges. A cell whose Chebyshev ball inside the envelope has radius at most
:data:`~.polyhedra.EMPTY_RADIUS` half-widths is dropped and listed in ``dropped_modes``;
redundant rows are removed by linear programs (:func:`~.polyhedra.irredundant_rows`).

**Ties.** The closed regions overlap on their boundaries. The modes keep the fitted model's
order (its region index, lexicographically over partitions), so the rule "the
lowest-numbered region that holds z" (:meth:`PWAStateSpace.mode_of`) is the model's own: an
argmax picks the lowest index among equal scores, a sign test puts 0 with bit 0, and the
lowest product cell is the product of the lowest regions.
"""

import itertools
from dataclasses import dataclass

import numpy as np
from sklearn.utils.validation import check_is_fitted

from .._typing import Float2D, Signals
from .._validation import as_experiments
from ..envelope import PADDING, channel_bounds, regressor_bounds
from .polyhedra import EMPTY_RADIUS, Box, chebyshev_ball, irredundant_rows
from .state_space import PWAStateSpace


@dataclass
class Partition:
    """One partition of φ-space into closed regions {φ : G φ ≤ q}.

    Attributes
    ----------
    labels : ndarray of int, shape (s,)
        The fitted model's index of each region.
    rows : list of (ndarray of shape (k, D), ndarray of shape (k,))
        (G, q) of each region, over φ.
    outputs : list of int
        The outputs whose sub-model is chosen by this partition.
    """

    labels: np.ndarray
    rows: list[tuple[Float2D, np.ndarray]]
    outputs: list[int]

    def same_as(self, other: "Partition") -> bool:
        """Whether both have the same regions, row for row."""
        return (np.array_equal(self.labels, other.labels) and len(self.rows) == len(other.rows)
                and all(np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
                        for a, b in zip(self.rows, other.rows, strict=True)))


def single_partition(d: int, label: int = 0) -> Partition:
    """One region, all of φ-space (a linear model)."""
    return Partition(np.array([label]), [(np.zeros((0, d)), np.zeros(0))], [])


def argmax_partition(coef: Float2D, intercept: np.ndarray, n_regions: int) -> Partition:
    """The regions of φ ∈ H_i ⇔ i = argmax_j (w_j·φ + b_j) (see the module doc).

    Parameters
    ----------
    coef : ndarray of shape (s, D)
    intercept : ndarray of shape (s,)
        −inf marks a region that is never chosen (it gets no region).
    n_regions : int
        s; with one region, the whole space (as :meth:`SVMRegions.predict
        <pwa_pipeline.pwa.steps.regions.SVMRegions.predict>`).
    """
    d = coef.shape[1]
    live = np.flatnonzero(np.isfinite(intercept))
    if n_regions == 1 or live.size <= 1:
        return single_partition(d, int(live[0]) if live.size == 1 and n_regions > 1 else 0)
    rows = []
    for i in live:
        others = live[live != i]
        rows.append((coef[others] - coef[i], intercept[i] - intercept[others]))
    return Partition(live.copy(), rows, [])


def sign_partition(weights: Float2D) -> Partition:
    """The 2^v regions Σ_v 2^v [w_vᵀφ > 0] of :class:`~pwa_pipeline.pwa.scheduling.
    SignRegions` (see the module doc)."""
    v, d = weights.shape
    rows = []
    for label in range(2 ** v):
        bits = (label >> np.arange(v)) & 1
        sign = np.where(bits == 1, -1.0, 1.0)
        rows.append((weights * sign[:, None], np.zeros(v)))
    return Partition(np.arange(2 ** v), rows, [])


def _argmax_step(step, what: str) -> None:
    """NotImplementedError unless ``step`` predicts by SVMRegions' argmax."""
    from ..pwa.steps.regions import SVMRegions

    if not isinstance(step, SVMRegions) or type(step).predict is not SVMRegions.predict:
        raise NotImplementedError(
            f"to_state_space: {what} uses the region step {type(step).__name__}, whose "
            f"predict is not the argmax of affine functions of SVMRegions; only that rule "
            f"(SVMRegions, ResidualRegions) and sign scheduling are converted to polyhedra")


@dataclass
class ModelParts:
    """What :func:`to_state_space` reads from a fitted model.

    Attributes
    ----------
    partitions : list of Partition
        One per output (possibly the same object for several).
    theta : callable
        ``theta(p, label)`` → the row Θ_{p,label} over φ, shape (D,).
    output_lags, input_lags : int
    affine : bool
    source : dict
    """

    partitions: list[Partition]
    theta: object
    output_lags: int
    input_lags: int
    affine: bool
    source: dict


def model_parts(model) -> ModelParts:
    """The partitions and parameter rows of a fitted PWARX or LinearARX (any route).

    Raises
    ------
    NotImplementedError
        For another model class, or a route whose regions are not argmax or sign regions
        (a region step of one's own), naming it.
    """
    from ..baselines.linear import LinearARX
    from ..pwa.estimator import PWARX
    from ..pwa.scheduling import SignRegions
    from ..pwa.structure_fit import ProjectedRegions

    if not isinstance(model, PWARX | LinearARX):
        raise NotImplementedError(f"to_state_space converts PWARX and LinearARX models, not "
                                  f"{type(model).__name__}")
    check_is_fitted(model)
    m = model.n_outputs_
    lags, nb, affine = model.output_lags_, model.nb, model.affine
    d = m * lags + model.n_inputs_ * nb + int(affine)
    source = {"model": type(model).__name__, "na": model.na, "nb": nb, "affine": affine,
              "form": model.form, "outputs": model.outputs}
    if isinstance(model, LinearARX):
        theta = model.theta_
        source["route"] = "linear"
        part = single_partition(d)
        return ModelParts([part] * m, lambda p, label: theta[:, p], lags, nb, affine, source)
    if not model.structured:
        regions = model.regions_
        _argmax_step(regions, "the joint level route")
        thetas = model.thetas_
        source["route"] = f"joint level, regions of {type(regions).__name__}"
        part = argmax_partition(regions.coef_, regions.intercept_, regions.n_regions_)
        return ModelParts([part] * m, lambda p, label: thetas[label][:, p], lags, nb, affine,
                          source)
    structure = model.structure_
    parts, kinds = [], []
    for p, out in enumerate(structure.outputs):
        where = f"output {p + 1} of the {model.form} form, {model.outputs} outputs route"
        region_of = out.region_of
        if region_of is None:
            part = single_partition(d)
            kinds.append("one region")
        elif isinstance(region_of, ProjectedRegions):
            _argmax_step(region_of.predictor, where)
            pred = region_of.predictor
            part = argmax_partition(pred.coef_ @ region_of.M, pred.intercept_, pred.n_regions_)
            kinds.append(f"regions of {type(pred).__name__}")
        elif type(region_of) is SignRegions:
            part = sign_partition(region_of.weights)
            kinds.append("sign scheduling")
        else:
            raise NotImplementedError(
                f"to_state_space: {where} has regions of {type(region_of).__name__}, which "
                f"are not converted to polyhedra (argmax and sign regions are)")
        parts.append(part)
    thetas = structure.thetas
    source["route"] = (f"{model.form} form, {model.outputs} outputs, "
                       + ", ".join(sorted(set(kinds))))
    return ModelParts(parts, lambda p, label: thetas[p][label], lags, nb, affine, source)


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
    box of :func:`~pwa_pipeline.envelope.regressor_bounds` (φ without the constant),
    over u(k) each input's :func:`~pwa_pipeline.envelope.channel_bounds`.

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
    shape (2, m + r) (:func:`~pwa_pipeline.pwa.arx.training_range`)."""
    from ..pwa.arx import training_range

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
    u, y : array-like or lists of them, optional
        Data whose range makes the envelope (the training data). None: the model's
        ``signal_range_``, the range of its training data recorded at fit.
    padding : float, default :data:`~pwa_pipeline.envelope.PADDING` (0.05)
        Widening of the envelope beyond that range, a share of each channel's span.
    input_names, output_names : list of str, optional
        Names for the state's entries (default ``u1…``, ``y1…``).

    Returns
    -------
    PWAStateSpace

    Raises
    ------
    NotImplementedError
        For a model or route whose regions are not converted (named in the message).
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
    parts = model_parts(model)
    m, r = model.n_outputs_, model.n_inputs_
    lags, nb, affine = parts.output_lags, parts.input_lags, parts.affine
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

    # distinct partitions, and which one chooses each output's sub-model
    distinct: list[Partition] = []
    part_of = []
    for p, part in enumerate(parts.partitions):
        for k, known in enumerate(distinct):
            if known is part or known.same_as(part):
                part_of.append(k)
                known.outputs.append(p)
                break
        else:
            distinct.append(Partition(part.labels, part.rows, [p]))
            part_of.append(len(distinct) - 1)
    zrows = [[_to_z(G, q, n, r, affine) for G, q in part.rows] for part in distinct]

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

    mats = {name: [] for name in "ABfCg"}
    regions, mode_regions = [], []
    for index, G, q, centre in cells:
        labels = labels_of(index)
        theta = np.column_stack([parts.theta(p, labels[p]) for p in range(m)])
        for name, value in zip("ABfCg", mode_matrices(theta, m, r, lags, nb, affine),
                               strict=True):
            mats[name].append(value)
        Ht, ht = box.to_unit(np.vstack([G, box_H]), np.concatenate([q, box_h]))
        # a box row of a coordinate no other row involves always shapes the region
        touched = np.any(G != 0, axis=0)
        protected = np.concatenate([np.zeros(len(q), bool), ~touched, ~touched])
        keep = irredundant_rows(Ht, ht, protected, interior=centre)
        regions.append(box.from_unit(Ht[keep], ht[keep]))
        mode_regions.append(labels)
    return PWAStateSpace(
        np.array(mats["A"]), np.array(mats["B"]), np.array(mats["f"]), np.array(mats["C"]),
        np.array(mats["g"]), regions, box.lower, box.upper, output_lags=lags, input_lags=nb,
        affine=affine, input_names=input_names, output_names=output_names, padding=padding,
        mode_regions=mode_regions, dropped_modes=np.array(dropped, dtype=int).reshape(-1, m),
        source=parts.source)
