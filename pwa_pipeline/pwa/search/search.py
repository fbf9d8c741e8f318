"""Structure search: the model structure of a machine chosen from its data alone
([`auto`][pwa_pipeline.PWARX.auto]).

The paper's route (clustering local models, eq. 6–10, then an SVM) finds the modes of
systems whose sub-models differ a lot; on machines the switching is often a small change
(a friction offset that flips with the velocity's sign, an overflow, a saturating valve)
that the clustering misses, and a linear ARX model then wins. The search tries the
structures of [`structures`][pwa_pipeline.pwa.SearchReport.structures] and keeps what the data support:

1. **Hold out.** The last ``validation_fraction`` of the training experiments are held out
   (one record alone is split in time, `split_experiments`); everything is fitted on
   the others and judged by the free-run NRMSE (RMSE over the standard deviation, per
   output) on the held-out ones. The test record plays no part. When the held-out part
   is short (below 1,000 samples: a single short record) or ``n_folds`` asks for it, the
   shortlisted structures of steps 5–7 are also fitted without each earlier block and
   judged on it in turn (`folds`), and the lowest mean wins. A record longer than
   ``max_rows`` regressor rows is searched on an even subsample of its rows and refined on
   windows of it (`windows`); the shortlisted structures are fitted on every row.
2. **Linear.** Least-squares linear models over every form (level, velocity) and every
   order pair within the bounds, joint (eq. 1) or one model per output (each output its
   own form and orders): the best is the linear reference, and its coupling the one the
   next steps use.
3. **Scheduled regions.** Per output, greedily, the scheduling variable z = wᵀφ that lowers
   the held-out error most, from variables the search proposes itself: the sign of each
   output's increment (velocity sign, Coulomb friction), thresholds of each output and
   input at quantiles of its training values (overflows, saturations, configurations),
   the sign of each input and of its increment (dead zones, backlash); with either every
   parameter switching (``"all"``) or the constant only (``"offset"``). A variable is kept
   only when it lowers the error by ``min_gain`` (relative), at most ``max_variables`` per
   output (2^v regions).
4. **Clusters.** The paper's steps 2–6 on the linear reference's regressors ψ (the
   estimator's steps), a candidate beside the scheduled regions.
5. **Refinement.** The last two structures the greedy step kept (the richest and the one
   before), the clustered one and the linear reference are refined on the free-run error
   with the one-step error kept in the objective (`output_error`,
   ``one_step_weight``): on a machine the least-squares free run can rank structures
   otherwise than the refined one. Each runs on the fitting experiments alone to its
   tolerance or ``max_iter``; the held-out experiments only judge it. Choosing the iterate
   on them too would let the richer candidates fit the segment that then ranks them.
6. **Never worse than linear.** Per output group, the refined structure with the lowest
   held-out free-run NRMSE is kept only if it beats the refined linear reference;
   otherwise the linear model is returned, and the report says so.
7. **Never worse than the default.** The library default [`PWARX`][pwa_pipeline.PWARX] of the
   largest orders (the paper's steps 2–6 on eq. (3)'s φ), fitted on the same experiments,
   and the same with the constant (by the search's clustering steps), replace the
   search's choice when their held-out free run is better: a user never gets a worse
   model from the search than the default one.

Every candidate is a row of [`SearchReport.table`][pwa_pipeline.pwa.SearchReport.table], with its held-out
NRMSE and what became of it (kept, not better by ``min_gain``, diverged, skipped and why). A candidate
whose free run diverges is skipped.

The search is budgeted in work, not seconds, so that the same data give the same model on
a busy or a quiet machine: it measures at most ``max_candidates`` candidate structures
(each a least-squares fit and a held-out free run), and the refinements stop by their
iteration count and tolerance. When the budget is spent the search stops proposing, the
candidates already measured compete (refined as usual), the best of them is kept and the
report says so. ``max_seconds`` is only a safety net: past it the remaining candidates
compete unrefined, and the report warns that the result then depends on the machine's
speed.
"""

import logging
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from numbers import Integral, Real

import numpy as np
import pandas as pd
from sklearn.base import BaseEstimator
from sklearn.utils._param_validation import HasMethods, Interval, StrOptions

from ..._typing import Float2D
from ...regressors import build_regressors
from ...scoring.evaluation import WARMUP
from ..kernels.free_run import pack_regions, region_free_run
from ..limits import all_bounds, has_limits
from ..output_error import OutputErrorRefinement, held_out, numbered, refine_outputs
from ..output_error.simulator import FreeRuns
from ..partitions import SignRegions
from ..structure_fit import StructureFit, clustered_models
from ..structures import (
    COUPLINGS,
    FORMS,
    OutputModel,
    assign_params,
    output_regressors,
    phi_names,
    switching_entries,
)

#: Which parameters may differ between scheduled regions (see `OutputModel`):
#: the constant, all, or none with a hinge per variable (a continuous map).
SWITCH_OPTIONS = ("offset", "all", "continuous")
#: The switches tried by default.
SWITCHES = ("offset", "all")
#: Quantiles of a signal's training values at which thresholds are proposed.
QUANTILES = (0.1, 0.25, 0.5, 0.75, 0.9)
#: Held-out NRMSE above which a free run counts as diverged (as the evaluation's).
DIVERGED = 10.0
#: Hinge steps at most per kept oblique boundary (`_Search.hinge`).
HINGE_STEPS = 3
#: Samples per window of a long record's refinement (`windows`, ``max_rows``).
WINDOW = 2000
#: Fewest training rows a scheduled region needs per parameter it switches.
ROWS_PER_PARAMETER = 3
#: Held-out samples the shortlist is judged on at least with ``n_folds="auto"``: as many
#: held-out blocks as it takes, at most `AUTO_FOLDS` (`folds`).
JUDGED = 1000
AUTO_FOLDS = 5
#: The standard-library logger of the search's progress: a line per stage at INFO.
SEARCH_LOG = __name__
_log = logging.getLogger(SEARCH_LOG)


class SearchTimeLimit(UserWarning):
    """The structure search reached its safety net ``max_seconds`` and kept the best
    structure so far (a result that depends on the machine's speed)."""


class SearchBudgetSpent(UserWarning):
    """The structure search measured ``max_candidates`` candidates and kept the best of
    them (the same on any machine)."""


@dataclass(frozen=True)
class Variable:
    """A scheduling variable z(k) = wᵀφ(k) proposed by the search.

    Attributes
    ----------
    name : str
        As the report writes it, e.g. ``"Δy1(k-1) > 0"`` or ``"u2(k-1) > 0.31"``.
    weights : ndarray of shape (D,)
        w over φ's entries.
    """

    name: str
    weights: np.ndarray = field(repr=False)


@dataclass(frozen=True)
class OutputSpec:
    """One output's structure: form, orders, scheduling variables and what switches."""

    form: str
    na: int
    nb: int
    variables: tuple[Variable, ...] = ()
    switch: str = "linear"

    def describe(self) -> str:
        """E.g. ``"velocity (2, 1), offset on [Δy1(k-1) > 0]"``."""
        base = f"{self.form} ({self.na}, {self.nb})"
        if self.switch == "clustered":
            return f"{base}, clustered"
        if not self.variables:
            return f"{base}, linear"
        if self.switch == "continuous":
            bends = ", ".join(v.name.replace(" > ", " = ") for v in self.variables)
            return f"{base}, continuous, slopes bend at [{bends}]"
        return f"{base}, {self.switch} on [{', '.join(v.name for v in self.variables)}]"


@dataclass(frozen=True)
class SearchReport:
    """What the structure search tried and why it chose.

    Attributes
    ----------
    table : pandas.DataFrame
        One row per candidate: ``stage`` (linear, scheduled, clustered, refined,
        cross-validated (a shortlisted structure over the held-out blocks, each block's
        figure in ``outcome``), default, chosen; ``searched`` for the search's own choice
        when the default PWARX beat it),
        ``outputs``, ``structure`` (form, orders, regions), ``regions`` (count),
        ``validation_nrmse`` (held-out free run, mean over the outputs), ``outcome``,
        ``seconds`` (since the search started).
    choice : str
        Per output group, the structure kept and why, in a sentence each.
    structures : list of str
        Each output's structure as the table writes it (form, orders, regions).
    linear : bool
        Whether every output kept its linear model: the search returns the linear ARX
        model (no switching structure beat it on the held-out experiments). `verdict`
        says it in a line.
    n_candidates : int
        Candidate structures measured (least squares and a held-out free run each).
    budget_spent : bool
        Whether ``max_candidates`` stopped the search's proposals (the best candidate
        measured was kept).
    time_limited : bool
        Whether the safety net ``max_seconds`` stopped the search (the best structure so
        far was kept, unrefined where the limit came first).
    validation_nrmse : float
        The returned model's held-out free-run NRMSE (mean over outputs).
    linear_nrmse : float
        The refined linear reference's.
    seconds : float
    """

    table: pd.DataFrame
    choice: str
    structures: list[str]
    linear: bool
    n_candidates: int
    budget_spent: bool
    time_limited: bool
    validation_nrmse: float
    linear_nrmse: float
    seconds: float

    @property
    def verdict(self) -> str:
        """What the model is, in a line (the leaderboard's row and the model's page show it
        beside the method's name): the linear model kept or a switching structure, and,
        when the budget ``max_candidates`` or the time limit ``max_seconds`` stopped the
        search, that it did."""
        if self.time_limited:
            stop = "the search stopped at its time limit"
        elif self.budget_spent:
            stop = "the search spent its budget of candidates"
        else:
            return ("linear kept (no switching structure beat it held out)" if self.linear
                    else "switching structure kept (it beat the linear model held out)")
        return (f"linear kept: {stop} before a switching structure beat it" if self.linear
                else f"switching structure kept: {stop}, the best found kept")

    def summary(self) -> pd.DataFrame:
        """The rows that decided: the best linear candidate of each coupling, the variables
        kept, the clustered candidates, the refinements, each shortlisted structure over the
        held-out blocks (with several) and the choices (a linear row's outcome says which
        coupling it is the best of)."""
        t = self.table
        linear = t[t.stage == "linear"]
        best = [g.validation_nrmse.idxmin() for _, g in linear.groupby(["outputs", "outcome"])
                if g.validation_nrmse.notna().any()]
        decided = t.stage.isin(["clustered", "refined", "cross-validated", "default",
                                "searched", "chosen"]) \
            | t.outcome.str.startswith("kept")
        out = t.loc[sorted(set(best) | set(t.index[decided]))].copy()
        out.loc[out.stage == "linear", "outcome"] = \
            "best " + out.outcome[out.stage == "linear"] + " linear"
        return out


def split_experiments(experiments: list, fraction: float, min_samples: int
                      ) -> tuple[list, list, str]:
    """The experiments to fit on and those held out (the first of `folds`).

    The last ``round(fraction · n)`` experiments (at least one) are held out. A single
    record is split in time instead: its last ``fraction`` of samples becomes a held-out
    experiment of its own (its first samples serve as its warm-up).

    Returns
    -------
    fit, held : lists of (u, y)
    how : str
        The split, in words, for the report.

    Raises
    ------
    ValueError
        When a single record is too short to split into two parts of ``min_samples``
        samples each (the message gives the lengths needed).
    """
    n = len(experiments)
    if n >= 2:
        n_val = held_out(n, fraction)
        return (experiments[:n - n_val], experiments[n - n_val:],
                f"experiment{'s' if n_val > 1 else ''} "
                f"{numbered(list(range(n - n_val, n)), n)} held out")
    u, y = experiments[0]
    cut = int(round(len(y) * (1 - fraction)))
    if cut < min_samples or len(y) - cut < min_samples:
        needed = int(np.ceil(min_samples / min(fraction, 1 - fraction)))
        raise ValueError(
            f"the structure search holds out part of the training data and needs at least "
            f"2 experiments, or one record of at least {needed} samples to split in time; "
            f"got one record of {len(y)} samples")
    return ([(u[:cut], y[:cut])], [(u[cut:], y[cut:])],
            f"a single record: its last {len(y) - cut} of {len(y)} samples held out")


def folds(experiments: list, fraction: float, n_folds: int | str, min_samples: int
          ) -> tuple[list[tuple[list, list]], str]:
    """Blocked cross-validation folds: (fit, held) pairs, the first that of
    `split_experiments`, each next one holding out the block before; with the first
    split in words (as `split_experiments` says it).

    ``n_folds="auto"`` takes as many as hold out `JUDGED` samples in all, at most
    `AUTO_FOLDS`: five blocks of a 1,000-sample record's 200, one block where the held-out
    experiments hold 1,000 samples or more. A short held-out part ranks the candidates by
    a few hundred samples, and its best candidate is often the one that fits them by
    chance.

    Blocks keep time order (no sample is predicted from its future's fit, and a drift is
    judged over a whole block): with several experiments a block is ``round(fraction·n)``
    consecutive experiments; a single record is cut in blocks of its held-out length, and
    the samples before and after a held block are fitted as two experiments (a part
    shorter than ``min_samples`` is left out). At most ``n_folds`` folds, as many as
    whole blocks fit in the data.
    """
    fit, held, how = split_experiments(experiments, fraction, min_samples)
    if n_folds == "auto":
        n_folds = min(AUTO_FOLDS, -(-JUDGED // sum(len(y) for _, y in held)))
    out = [(fit, held)]
    n = len(experiments)
    if n >= 2:
        size = len(held)
        for i in range(1, n_folds):
            start = n - (i + 1) * size
            if start < 0:
                break
            out.append((experiments[:start] + experiments[start + size:],
                        experiments[start:start + size]))
        return out, how
    u, y = experiments[0]
    size = len(held[0][1])
    for i in range(1, n_folds):
        start = len(y) - (i + 1) * size
        if start < 0:
            break
        end = start + size
        parts = [(u[a:b], y[a:b]) for a, b in ((0, start), (end, len(y)))
                 if b - a >= min_samples]
        out.append((parts, [(u[start:end], y[start:end])]))
    return out, how


class _HeldOut:
    """The held-out experiments, simulated in lockstep for the NRMSE of candidate models."""

    def __init__(self, experiments: list, lags: int, nb: int, warmup: int,
                 limits: Float2D | None = None):
        u, y = [e[0] for e in experiments], [e[1] for e in experiments]
        self.runs = FreeRuns(u, y, lags, nb, True, warmup, limits=limits)
        self.warmup = warmup
        scored = np.vstack([ye[warmup:] for ye in y])
        self.std = scored.std(axis=0)
        self.std[self.std == 0] = 1.0
        self.u, self.y = u, y
        #: Samples scored per output.
        self.count = int(np.maximum(self.runs.lengths - warmup, 0).sum())

    def nrmse(self, models: dict[int, OutputModel], group: list[int]) -> np.ndarray:
        """Free-run NRMSE of each output of ``group`` (the others measured), inf where the
        run diverges: compiled (`free_run`) for models whose
        regions have a compiled form (linear, sign-scheduled, clustered), else by
        `simulated_sse`."""
        forms = [models[j].compiled_regions() for j in group]
        if all(f is not None for f in forms):
            sse = self.compiled_sse(models, group, forms)
        else:
            sse = self.simulated_sse(models, group)
        out = np.sqrt(sse / max(self.count, 1)) / self.std[group]
        return np.where(out > DIVERGED, np.inf, out)

    def compiled_sse(self, models: dict[int, OutputModel], group: list[int],
                     forms: list | None = None) -> np.ndarray:
        """Sums of squared free-run errors of models whose regions have a compiled form
        (``forms``, default read from the models), by the compiled kernel."""
        runs = self.runs
        forms = [models[j].compiled_regions() for j in group] if forms is None else forms
        thetas = [models[j].thetas() for j in group]
        d = thetas[0].shape[1]
        packed_t = np.zeros((len(group), max(len(t) for t in thetas), d))
        for jj, t in enumerate(thetas):
            packed_t[jj, :len(t)] = t
        return region_free_run(runs.y, runs.u, runs.lengths.astype(np.int64), self.warmup,
                               runs.na, runs.nb, np.array(group, dtype=np.int64), packed_t,
                               *pack_regions(forms, d), runs.lower, runs.upper)

    def simulated_sse(self, models: dict[int, OutputModel], group: list[int]) -> np.ndarray:
        """Sums of squared free-run errors of any models, every experiment in lockstep
        (numpy, a step per sample)."""
        runs, w = self.runs, self.warmup
        ysim = runs.y.copy()
        thetas = [models[j].thetas() for j in group]
        sse = np.zeros(len(group))
        with np.errstate(over="ignore", invalid="ignore"):
            for k in range(w, ysim.shape[1]):
                active = runs.lengths > k
                phi = runs.phi(ysim, k)
                for jj, j in enumerate(group):
                    yk = np.clip(np.einsum("ed,ed->e", phi, thetas[jj][models[j].regions(phi)]),
                                 runs.lower[j], runs.upper[j])
                    target = runs.y[:, k, j]
                    ysim[:, k, j] = np.where(active, yk, target)
                    sse[jj] += float(np.sum(np.where(active, yk - target, 0.0) ** 2))
                if not np.all(np.isfinite(sse)):
                    return np.full(len(group), np.inf)
        return sse


def windows(experiments: list, max_samples: int | None, length: int = WINDOW) -> list:
    """The experiments the refinement runs on: all of them, or, past ``max_samples``
    samples, windows of ``length`` samples (whole experiments when shorter) evenly spread
    over them, ``max_samples`` at most in all; each window's first samples are its
    warm-up, as an experiment's."""
    lengths = np.array([len(e[1]) for e in experiments])
    total = int(lengths.sum())
    if max_samples is None or total <= max_samples:
        return experiments
    offsets = np.concatenate([[0], np.cumsum(lengths)])
    chosen: dict[tuple[int, int], tuple] = {}
    size = int(min(length, np.median(lengths)))  # a window's samples, typically
    for start in np.linspace(0, total - 1, max(1, max_samples // size)).astype(int):
        i = int(np.searchsorted(offsets, start, side="right")) - 1
        local = int(max(0, min(start - offsets[i], lengths[i] - length)))
        u, y = experiments[i]
        chosen.setdefault((i, local), (u[local:local + length], y[local:local + length]))
    return list(chosen.values())


class _Fold:
    """One cross-validation fold: the regressors of its fitting experiments, the
    experiments its refinements run on (`windows`) and its held-out block."""

    def __init__(self, fit: list, held: list, lags: int, nb: int, warmup: int,
                 max_samples: int | None, limits: Float2D | None = None):
        train = windows(fit, max_samples)
        self.u, self.y = [e[0] for e in train], [e[1] for e in train]
        self.reg = build_regressors(fit, lags, nb, True)
        self.held = _HeldOut(held, lags, nb, warmup, limits)

    def cost(self, models: dict[int, OutputModel], group: list[int]) -> float:
        """Held-out free-run NRMSE of the group's models, mean over its outputs."""
        return float(np.mean(self.held.nrmse(models, group)))


class StructureSearch(BaseEstimator):
    """Search of a PWARX structure on held-out training experiments (see the module doc).

    The search step of [`PWARX`][pwa_pipeline.PWARX] (``search=``; [`PWARX.auto`][pwa_pipeline.PWARX.auto]
    builds one): the estimator's ``na`` and ``nb`` are the largest orders tried.

    Parameters
    ----------
    forms : list of {"level", "velocity"}, default both
    couplings : list of {"joint", "decoupled"}, default both
    max_variables : int, default 2
        Scheduling variables per output at most (2^v regions).
    switches : list of {"offset", "all", "continuous"}, default ["offset", "all"]
        What a scheduling variable changes: the constant only, every parameter, or the
        slopes continuously (a hinge γ max(0, z) per variable, `structures`: a smooth
        nonlinearity such as a square-root outflow gets bending slopes rather than
        jumping offsets).
    min_gain : float, default 0.02
        Relative lowering of the held-out NRMSE a richer structure must bring.
    oblique : bool, default True
        Also propose oblique boundaries: thresholds of each output's linear one-step
        prediction ŷ = θᵀφ (a level a combination of outputs and inputs reaches), and
        move a kept one to the hinge of its two pieces (Breiman 1993), where a continuous
        nonlinearity (a saturation, an overflow) switches. On the simulated machines'
        tuning seeds (``benchmarks/auto_tuning.py``) it lowered the DC motor's median
        free-run NRMSE from 0.112 to 0.110 and left the arm's and the tanks' as they were;
        on the robot's training experiments (``benchmarks/robot_auto_tuning.py``) it scored
        0.692 against 0.682 without.
    clustering : bool, default True
        Also try the paper's clustered regions (the estimator's steps 2–6) on the chosen
        regressors, and compare the result with the default PWARX of the largest orders
        (module doc, stage 7).
    refinement : OutputErrorRefinement, optional
        Refines the best structure and the linear reference on the free-run error, on the
        fitting experiments to its tolerance or ``max_iter`` (its ``validation_fraction``
        and ``patience`` are not used: the held-out experiments only judge). None:
        ``OutputErrorRefinement(max_iter=30, one_step_weight=0.001)``.
    validation_fraction : float, default 0.2
        Share of the training experiments held out (the last ones).
    n_folds : int or "auto", default "auto"
        Held-out blocks the shortlisted structures are judged on in turn (blocked
        cross-validation, `folds`): the search proposes on the first (the last
        ``validation_fraction`` of the data), then the linear reference, the refined
        candidates and the default PWARX are fitted again without each other block,
        refined and judged on it, and the lowest mean held-out NRMSE wins. At most as many
        as whole blocks fit in the data. ``"auto"`` takes as many blocks as hold out 1,000
        samples in all (`JUDGED`), at most 5: five of a 1,000-sample record, three of a
        2,000-sample one, one wherever the held-out experiments hold 1,000 samples (the
        robot's, EMPS', the simulated machines' 40 experiments). On single records of the
        simulated machines' tuning seeds (``benchmarks/auto_tuning.py``, 1,000 samples)
        one block let the search lose to the best linear ARX on one seed in 18 (0.488
        against 0.318) and five blocks on none; with many experiments five blocks chose
        the same model on 7 of 9 seeds, a worse one on one, and scored the robot's training
        experiments 0.699 against 0.692 at twice the search's time, so there one block
        judges.
    max_rows : int or None, default 50000
        Regressor rows the candidates are fitted on at most, and samples the refinements
        run on: past it the candidates are fitted on one row in k (an even subsample,
        each row keeping its own lags) and the shortlisted ones fitted again on every row,
        and the refinements run on windows of 2,000 samples (or whole shorter
        experiments) evenly spread over the data (`windows`); the held-out blocks
        are simulated whole. A 400,000-sample record is then searched in about 15 s. The
        default leaves the robot's 32,000 rows and EMPS's 20,000 whole: on the robot's
        training experiments (``benchmarks/robot_auto_tuning.py``) 20,000 gave 0.721
        against 0.692. None: every row and sample.
    refit : bool, default False
        Fit the chosen structure again on every training experiment, the held-out ones
        included (least squares in its regions, then the refinement to its tolerance or
        ``max_iter``). Off by default: on the robot's training experiments (fitted on
        0–58, scored on 59–65; ``benchmarks/robot_auto_tuning.py``) it lowered the free-run
        NRMSE from 0.692 to 0.688, and on the simulated machines' tuning seeds
        (``benchmarks/auto_tuning.py``) each machine's median a little (the two tanks'
        from 0.048 to 0.044), but it raised one arm seed's from 0.120 to 0.131 and two of
        the DC motor's seeds' by 2–3 %.
    max_candidates : int, default 2000
        The search's budget of work: candidate structures measured at most (each a
        least-squares fit and a held-out free run; the linear stage is measured whole
        whatever the budget). Once spent, the search stops proposing, the best candidate
        measured is kept (refined as usual) and [`SearchBudgetSpent`][pwa_pipeline.pwa.SearchBudgetSpent]
        warned. The default lets the robot's search (six outputs, six inputs, orders up to 2: about
        1,120 candidates) finish.
    max_seconds : float, default 900
        A safety net, not the budget: past it (a fit may pass it by the candidate and the
        refinement under way) the remaining candidates compete unrefined, the best is kept
        and [`SearchTimeLimit`][pwa_pipeline.pwa.SearchTimeLimit] warned: a result that then depends on the
        machine's speed.
    """

    _parameter_constraints: dict = {
        "forms": [list, tuple],
        "couplings": [list, tuple],
        "max_variables": [Interval(Integral, 0, 4, closed="both")],
        "switches": [list, tuple],
        "min_gain": [Interval(Real, 0, 1, closed="left")],
        "oblique": ["boolean"],
        "clustering": ["boolean"],
        "refinement": [HasMethods(["fit"]), None, StrOptions({"none"})],
        "validation_fraction": [Interval(Real, 0, 1, closed="neither")],
        "n_folds": [Interval(Integral, 1, None, closed="left"), StrOptions({"auto"})],
        "max_rows": [Interval(Integral, 100, None, closed="left"), None],
        "refit": ["boolean"],
        "max_candidates": [Interval(Integral, 1, None, closed="left")],
        "max_seconds": [Interval(Real, 0, None, closed="neither")],
    }

    def __init__(self, forms=FORMS, couplings=COUPLINGS, max_variables: int = 2,
                 switches=SWITCHES, min_gain: float = 0.02, oblique: bool = True,
                 clustering: bool = True,
                 refinement: BaseEstimator | str | None = None,
                 validation_fraction: float = 0.2, n_folds: int | str = "auto",
                 max_rows: int | None = 50000, refit: bool = False,
                 max_candidates: int = 2000, max_seconds: float = 900.0):
        self.forms = forms
        self.couplings = couplings
        self.max_variables = max_variables
        self.switches = switches
        self.min_gain = min_gain
        self.oblique = oblique
        self.clustering = clustering
        self.refinement = refinement
        self.validation_fraction = validation_fraction
        self.n_folds = n_folds
        self.max_rows = max_rows
        self.refit = refit
        self.max_candidates = max_candidates
        self.max_seconds = max_seconds

    def _check(self) -> None:
        self._validate_params()
        for name, allowed in (("forms", FORMS), ("couplings", COUPLINGS),
                              ("switches", SWITCH_OPTIONS)):
            values = list(getattr(self, name))
            bad = [v for v in values if v not in allowed]
            if not values or bad:
                raise ValueError(f"StructureSearch {name} must be a non-empty list of "
                                 f"{list(allowed)}; got {values}")

    def refinement_step(self) -> OutputErrorRefinement | None:
        """The refinement the search runs (None with ``refinement="none"``)."""
        if self.refinement == "none":
            return None
        if self.refinement is None:
            return OutputErrorRefinement(max_iter=30, one_step_weight=0.001)
        return self.refinement

    def search(self, experiments: list[tuple[Float2D, Float2D]], na: int, nb: int,
               cluster: Callable | None = None, default: Callable | None = None,
               limits: Float2D | None = None) -> tuple[StructureFit, SearchReport]:
        """Search the structure (module doc) on the experiments, orders up to (na, nb).

        Parameters
        ----------
        experiments : list of (u, y)
        na, nb : int
            Largest orders (na ≥ 1, nb ≥ 1); φ holds na + 1 output lags (the velocity form's
            level) and nb input lags, and the constant.
        cluster : callable, optional
            ``cluster(reg)`` → (θ (s, d, group size), the fitted steps by name): the paper's
            steps 2–6 (the estimator passes its own); None: no clustered candidate.
        default : callable, optional
            As ``cluster``, the library default's steps on eq. (3)'s φ: the default PWARX
            of orders (na, nb) the result must not be worse than (the estimator passes
            it); None: no such check.
        limits : ndarray of shape (2, m), optional
            The outputs' limits (`pwa_pipeline.pwa.limits`): every candidate's free run,
            held out or refined, is clipped to them.

        Returns
        -------
        StructureFit, SearchReport

        Raises
        ------
        ValueError
            Orders below 1, too little data to hold any out (the message says how much is
            needed), or when every linear candidate diverges on the held-out experiments.
        """
        self._check()
        if na < 1 or nb < 1:
            raise ValueError(f"the structure search needs na >= 1 and nb >= 1 as its largest "
                             f"orders; got na={na}, nb={nb}")
        return _Search(self, experiments, na, nb, cluster, default, limits).run()


class _Search:
    """One run of [`StructureSearch.search`][pwa_pipeline.pwa.StructureSearch.search]."""

    def __init__(self, params: StructureSearch, experiments: list, na: int, nb: int,
                 cluster: Callable | None, default: Callable | None,
                 limits: Float2D | None = None):
        self.p, self.na, self.nb, self.limits = params, na, nb, limits
        self.cluster, self.default = cluster, default
        self.t0 = time.perf_counter()
        self.lags = na + 1
        self.warmup = max(self.lags, nb, WARMUP)
        self.m, self.r = experiments[0][1].shape[1], experiments[0][0].shape[1]
        min_samples = self.warmup + 20
        blocks, self.split = folds(experiments, params.validation_fraction, params.n_folds,
                                   min_samples)
        self.fit_exp, self.held_exp = blocks[0]
        self.n_experiments = len(experiments)
        for i, (_, y) in enumerate(self.held_exp, len(experiments) - len(self.held_exp)):
            if len(y) < min_samples:  # else nothing, or too little, is scored: NaN costs
                raise ValueError(
                    f"held-out experiment {i} has {len(y)} sample(s): the structure search "
                    f"scores the free run of each held-out experiment after a warm-up of "
                    f"{self.warmup} samples and needs at least {min_samples} (it holds out "
                    f"the last {len(self.held_exp)} of {len(experiments)}); lengthen it, "
                    f"join it to another or leave it out")
        self.n_fit = len(self.fit_exp)
        self.folds = [_Fold(fit, held, self.lags, nb, self.warmup, params.max_rows, limits)
                      for fit, held in blocks]
        full, self.held = self.folds[0].reg, self.folds[0].held
        if full.phi.shape[0] < 2 * full.phi.shape[1]:
            raise ValueError(f"too few samples for the structure search: "
                             f"{full.phi.shape[0]} regressor rows for "
                             f"{full.phi.shape[1]} regressor entries")
        n_rows = full.phi.shape[0]
        #: Every stride-th regressor row is what the candidates are fitted on.
        self.stride = 1 if params.max_rows is None else -(-n_rows // params.max_rows)
        self.reg = full if self.stride == 1 else full.subset(np.arange(0, n_rows, self.stride))
        if self.stride > 1:
            self.split += (f"; candidates fitted on one in {self.stride} of the {n_rows} "
                           f"regressor rows (max_rows), the shortlisted ones on all and "
                           f"refined on {sum(len(y) for y in self.folds[0].y)} samples")
        if len(self.folds) > 1:
            self.split += (f"; the shortlisted structures judged on {len(self.folds)} "
                           f"held-out blocks in turn")
        if params.n_folds != "auto" and len(self.folds) < params.n_folds:
            self.split += (f" (n_folds={params.n_folds} asked: only {len(self.folds)} whole "
                           f"block{'s' if len(self.folds) > 1 else ''} of the held-out "
                           f"size fit in the data)")
        if has_limits(limits):
            held = all_bounds(limits, [f"y{j + 1}" for j in range(self.m)])
            self.split += f"; every free run held at the outputs' limits ({held})"
        self.names = phi_names(self.m, self.r, self.lags, nb, True)
        self.rows: list[dict] = []
        self.n_candidates = 0
        self.budget_spent = False
        self.time_limited = False

    # -- helpers --------------------------------------------------------------------------
    def elapsed(self) -> str:
        """Candidates measured against the budget and seconds so far, for the progress
        lines."""
        return (f"{self.n_candidates} of at most {self.p.max_candidates} candidates, "
                f"{time.perf_counter() - self.t0:.0f} s")

    def late(self) -> bool:
        """Whether the safety net ``max_seconds`` has passed (sets the flag)."""
        if time.perf_counter() - self.t0 > self.p.max_seconds:
            self.time_limited = True
        return self.time_limited

    def stopped(self) -> bool:
        """Whether the search stops proposing: its budget of candidates spent, or the
        safety net passed (sets the flags)."""
        if self.n_candidates >= self.p.max_candidates:
            self.budget_spent = True
        return self.late() or self.budget_spent

    def stop_reason(self) -> str:
        """Why the search stopped proposing, as a clause for the report ("" if it did
        not)."""
        if self.time_limited:
            return (f"; stopped by the time limit (safety net) of {self.p.max_seconds:g} s "
                    f"after {self.n_candidates} candidates")
        if self.budget_spent:
            return f"; stopped by the budget of {self.p.max_candidates} candidates"
        return ""

    def measure(self, models: dict, group: list[int]) -> float:
        """A new candidate's held-out NRMSE, counted against the budget."""
        self.n_candidates += 1
        return self.cost(models, group)

    def record(self, stage: str, group: list[int], specs: dict, cost: float, outcome: str,
               models: dict | None = None) -> None:
        outputs = _outputs(group)
        structure = "; ".join(specs[j].describe() for j in group)
        regions = "" if models is None else "/".join(str(models[j].n_regions) for j in group)
        self.rows.append({"stage": stage, "outputs": outputs, "structure": structure,
                          "regions": regions, "validation_nrmse": cost, "outcome": outcome,
                          "seconds": round(time.perf_counter() - self.t0, 3)})

    def model(self, j: int, spec: OutputSpec, coupling: str) -> OutputModel:
        """Output j's model of ``spec``, least squares on the fitting rows."""
        M, c, names = output_regressors(j, self.m, self.r, spec.na, spec.nb, True, spec.form,
                                        coupling, phi_lags=self.lags, phi_nb=self.nb)
        if not spec.variables:
            om = OutputModel(M, c, np.zeros(len(names), bool), 1, None, "linear", names)
        else:
            sign = SignRegions(np.array([v.weights for v in spec.variables]))
            om = OutputModel(M, c, switching_entries(spec.switch, names), sign.n_regions_,
                             sign, spec.switch, names)
        return om.fit(self.reg.phi, self.reg.target[:, j])

    def on_all_rows(self, group: list[int], models: dict) -> dict:
        """The group's models fitted again, their regions kept, on every regressor row of
        the first fold when the candidates were fitted on a subsample (``max_rows``)."""
        if self.stride == 1:
            return models
        full = self.folds[0].reg
        return {**models, **{j: replace_p(models[j]).fit(full.phi, full.target[:, j])
                             for j in group}}

    def cost(self, models: dict, group: list[int]) -> float:
        """Held-out NRMSE of the group's models on the first fold (mean over outputs)."""
        return self.folds[0].cost(models, group)

    def judged(self) -> str:
        """Where the shortlisted candidates are judged, in words: the held-out
        experiments, or the held-out part of a single record (its split in time)."""
        if len(self.folds) > 1:
            return f"blocks of {len(self.folds)} folds"
        return "experiments" if self.n_experiments > 1 else "part of the record"

    def over_folds(self) -> str:
        """The clause saying that a figure is a mean over the folds ("" with one)."""
        return "" if len(self.folds) == 1 else f" (mean over {len(self.folds)} folds)"

    def fold_scores(self, group: list[int], shortlist: list[tuple]) -> list[float]:
        """The shortlisted candidates' scores: the held-out NRMSE of the first fold alone,
        or its mean over every fold (`cross_validated`, each recorded as a row);
        inf where a fold diverges."""
        if len(self.folds) == 1:
            return [c[0] for c in shortlist]
        scores = []
        for cost, specs, _, info, ls_models in shortlist:
            costs = self.cross_validated(group, ls_models, cost, refine=bool(info)) \
                if np.isfinite(cost) else [np.inf]
            scores.append(float(np.mean(costs)) if np.all(np.isfinite(costs)) else np.inf)
            self.record("cross-validated", group, specs, scores[-1],
                        f"mean of {len(self.folds)} folds: "
                        + ", ".join(f"{c:#.3g}" for c in costs), ls_models)
        return scores

    # -- stages ---------------------------------------------------------------------------
    def run(self) -> tuple[StructureFit, SearchReport]:
        linear, coupling = self.linear_stage()
        groups = [[j] for j in range(self.m)] if coupling == "decoupled" \
            else [list(range(self.m))]
        chosen: dict[int, OutputModel] = {}
        described: dict[int, str] = {}
        notes, refined_info = [], []
        lin_costs, final_costs = [], []
        _log.info(f"structure search: linear reference {coupling} "
                  f"({'; '.join(f'y{j + 1} {linear[j][0].describe()}' for j in range(self.m))}), "
                  f"{self.split}; refining it ({self.elapsed()})")
        # the linear reference of every group first: the fallback, whatever time remains
        references = [self.refined(group, {j: linear[j][0] for j in group},
                                   self.on_all_rows(group, {j: linear[j][1] for j in group}),
                                   "linear")
                      for group in groups]
        for group, (lin_cost, lin_models, lin_info) in zip(groups, references, strict=True):
            specs = {j: linear[j][0] for j in group}
            _log.info(f"structure search: {_outputs(group)}: scheduled regions and clusters "
                      f"({self.elapsed()})")
            path = self.scheduled_stage(group, specs, {j: linear[j][1] for j in group},
                                        coupling)
            candidates = path[-2:] + self.clustered_stage(group, specs, coupling)
            # (held-out NRMSE, specs, refined models, refinement info, least-squares models)
            shortlist = [(lin_cost, specs, lin_models, lin_info,
                          {j: linear[j][1] for j in group})]
            for cand_specs, cand_models in candidates:
                # past the time limit a candidate competes unrefined: a measured structure
                # better than the reference is never dropped for want of time
                cand_models = self.on_all_rows(group, cand_models)
                cost, models, info = self.refined(group, cand_specs, cand_models, "switching")
                shortlist.append((cost, cand_specs, models, info, cand_models))
            scores = self.fold_scores(group, shortlist)
            best = min(range(len(shortlist)), key=lambda i: (scores[i], i))
            best_cost, best_specs, best_models, best_info = shortlist[best][:4]
            keep = best > 0
            outcome = ("chosen: beats the linear model on the held-out " + self.judged()
                       if keep else
                       "chosen: linear (no switching structure measured beat it on the "
                       "held-out " + self.judged() + self.stop_reason() + ")")
            final_costs.append(scores[best])
            chosen.update(best_models)
            refined_info.append(best_info)
            lin_costs.append(scores[0])
            self.record("chosen", group, best_specs, final_costs[-1], outcome, best_models)
            for j in group:
                described[j] = best_specs[j].describe() + best_models[j].size()
            kept = "; ".join(f"y{j + 1}: {described[j]}" for j in group)
            notes.append(f"{kept}. Held-out free-run NRMSE {final_costs[-1]:#.4g}, refined "
                         f"linear reference {scores[0]:#.4g}" + self.over_folds() + "." +
                         ("" if keep else
                                                                 self.runner_up(group, lin_cost)))
            _log.info(f"structure search: {kept} (held-out NRMSE {final_costs[-1]:#.4g}, "
                      f"linear {scores[0]:#.4g}; {self.elapsed()})")
        weights = [len(g) for g in groups]
        final = float(np.average(final_costs, weights=weights))
        lin = float(np.average(lin_costs, weights=weights))
        default = self.default_stage(final)
        if default is not None:
            final, models, text = default
            groups, chosen = [list(range(self.m))], models
            described = dict.fromkeys(range(self.m), text)
            notes.append(f"The default PWARX ({text}) beats the search's choice on the "
                         f"held-out {self.judged()}: kept, held-out free-run NRMSE "
                         f"{final:#.4g}{self.over_folds()}.")
        if self.p.refit and not self.late():
            chosen = self.refit(groups, chosen)
        all_linear = all(o.structure == "linear" for o in chosen.values())
        outputs = ("One model for all outputs (joint)" if coupling == "joint"
                   else "One model per output (decoupled)")
        choice = (f"{outputs}; {self.split}. "
                  + ("Linear ARX: no switching structure beat it. " if all_linear else "")
                  + " ".join(notes))
        if self.time_limited:
            choice += (f" Time limit (safety net) of {self.p.max_seconds:g} s reached after "
                       f"{self.n_candidates} candidates: the best so far kept, a result that "
                       f"depends on the machine's speed (raise max_seconds).")
            warnings.warn(f"the structure search reached its time limit (safety net) of "
                          f"{self.p.max_seconds:g} s after {self.n_candidates} candidates "
                          f"and kept the best structure so far",
                          SearchTimeLimit, stacklevel=4)
        elif self.budget_spent:
            choice += (f" Budget of {self.p.max_candidates} candidates spent: the best "
                       f"measured kept (raise max_candidates to search further).")
            warnings.warn(f"the structure search measured its budget of "
                          f"{self.p.max_candidates} candidates (max_candidates) and kept "
                          f"the best of them", SearchBudgetSpent, stacklevel=4)
        seconds = time.perf_counter() - self.t0
        report = SearchReport(table=pd.DataFrame(self.rows), choice=choice,
                              structures=[described[j] for j in range(self.m)],
                              linear=all_linear, n_candidates=self.n_candidates,
                              budget_spent=self.budget_spent, time_limited=self.time_limited,
                              validation_nrmse=final, linear_nrmse=lin, seconds=seconds)
        n_val = self.n_experiments - self.n_fit
        fit = StructureFit(
            outputs=[chosen[j] for j in range(self.m)],
            validation_experiments=list(range(self.n_experiments - n_val, self.n_experiments)),
            validation_cost={}, refinement=[i for i in refined_info if i])
        return fit, report

    def linear_stage(self) -> tuple[dict[int, tuple[OutputSpec, OutputModel]], str]:
        """The best linear model per output (decoupled) and jointly; returns the better
        coupling's models and the coupling."""
        everything = list(range(self.m))
        orders = [(a, b) for a in range(1, self.na + 1) for b in range(1, self.nb + 1)]
        per_output: dict[int, tuple] = {}
        joint: tuple | None = None
        for form in self.p.forms:
            for a, b in orders:
                spec = OutputSpec(form, a, b)
                specs = dict.fromkeys(everything, spec)
                if "decoupled" in self.p.couplings:
                    for j in everything:
                        models = {j: self.model(j, spec, "decoupled")}
                        cost = self.measure(models, [j])
                        self.record("linear", [j], specs, cost, "decoupled", models)
                        if cost < per_output.get(j, (None, None, np.inf))[2]:
                            per_output[j] = (spec, models[j], cost)
                if "joint" in self.p.couplings:
                    models = {j: self.model(j, spec, "joint") for j in everything}
                    cost = self.measure(models, everything)
                    self.record("linear", everything, specs, cost, "joint", models)
                    if joint is None or cost < joint[0]:
                        joint = (cost, {j: (spec, models[j]) for j in everything})
        best_cost, best = {}, {}
        if len(per_output) == self.m:
            best_cost["decoupled"] = float(np.mean([per_output[j][2] for j in everything]))
            best["decoupled"] = {j: per_output[j][:2] for j in everything}
        if joint is not None:
            best_cost["joint"], best["joint"] = joint
        finite = {k: v for k, v in best_cost.items() if np.isfinite(v)}
        if not finite:
            raise ValueError("every linear candidate of the structure search diverges in "
                             "free run on the held-out experiments; check the data (units, "
                             "drifts) or lower the largest orders")
        coupling = min(finite, key=finite.get)
        return best[coupling], coupling

    def variables(self, j: int, coupling: str, linear: dict[int, OutputModel]
                  ) -> list[Variable]:
        """The scheduling variables output j's regions may read (``linear``: the group's
        linear reference models, whose one-step predictions give the oblique ones)."""
        out = []
        names, data = self.names, self.reg.phi
        const = np.zeros(len(names))
        const[-1] = 1.0

        def unit(name):
            e = np.zeros(len(names))
            e[names.index(name)] = 1.0
            return e

        def thresholds(column: str):
            values = data[:, names.index(column)]
            for t in np.unique(np.round(np.quantile(values, QUANTILES), 12)):
                out.append(Variable(f"{column} > {t:.4g}", unit(column) - t * const))

        # a decoupled output's regions read its own output only, so that its free run
        # depends on itself and the inputs alone
        own = [j] if coupling == "decoupled" else range(self.m)
        for q in own:
            y1, y2 = f"y{q + 1}(k-1)", f"y{q + 1}(k-2)"
            out.append(Variable(f"Δy{q + 1}(k-1) > 0", unit(y1) - unit(y2)))
            thresholds(y1)
        for q in range(self.r):
            u1 = f"u{q + 1}(k-1)"
            values = data[:, names.index(u1)]
            if values.min() < 0 < values.max():
                out.append(Variable(f"{u1} > 0", unit(u1)))
            thresholds(u1)
            if self.nb >= 2:
                out.append(Variable(f"Δu{q + 1}(k-1) > 0", unit(u1) - unit(f"u{q + 1}(k-2)")))
        if self.p.oblique:
            # thresholds of the linear one-step prediction ŷ_q(k) = θ_qᵀφ(k): a boundary
            # that a combination of levels and inputs reaches (an overflow, a saturation)
            for q in own:
                theta = linear[q].thetas()[0]
                predicted = data @ theta
                for t in np.unique(np.round(np.quantile(predicted, QUANTILES), 12)):
                    w = theta - t * const
                    out.append(Variable(f"ŷ{q + 1}: {oblique_name(w, names)}", w))
        return out

    def enough_rows(self, om: OutputModel) -> bool:
        """Whether every region of a scheduled model holds enough fitting rows (a
        continuous one: each side of each hinge, its regions may be empty)."""
        if om.structure == "continuous":
            need = ROWS_PER_PARAMETER * om.switching.size + 1
            above = (self.reg.phi @ om.hinges().T > 0).sum(axis=0)
            return bool(np.all(np.minimum(above, len(self.reg.phi) - above) >= need))
        need = ROWS_PER_PARAMETER * int(om.switching.sum()) + 1
        counts = np.bincount(om.regions(self.reg.phi), minlength=om.n_regions)
        return bool(counts.min() >= need)

    def scheduled_stage(self, group: list[int], specs: dict, models: dict, coupling: str
                        ) -> list[tuple[dict, dict]]:
        """Greedy choice of scheduling variables per output of the group: the structures
        kept in turn (specs and least-squares models by output), each with one variable
        more than the one before."""
        specs, models = dict(specs), dict(models)
        linear = dict(models)
        path = []
        current = self.cost(models, group)
        for j in group:
            pool = self.variables(j, coupling, linear)
            for _ in range(self.p.max_variables):
                if self.stopped():
                    break
                best = None
                for var in pool:
                    if var.name in {v.name for v in specs[j].variables}:
                        continue
                    for switch in self.p.switches:
                        if self.stopped():
                            break
                        spec = replace(specs[j], variables=specs[j].variables + (var,),
                                       switch=switch)
                        measured = self.try_spec(group, j, specs, models, spec, coupling)
                        if measured is None:
                            continue
                        cost, trial, tried = measured
                        outcome = "diverged" if not np.isfinite(cost) else "tried"
                        self.record("scheduled", group, tried, cost, outcome, trial)
                        if np.isfinite(cost) and (best is None or cost < best[0]):
                            best = (cost, spec, trial[j])
                if best is None or not best[0] < current * (1 - self.p.min_gain):
                    break
                current = best[0]
                specs[j], models[j] = best[1], best[2]
                self.record("scheduled", group, specs, current,
                            f"kept for y{j + 1}: lowers the held-out NRMSE by "
                            f"{self.p.min_gain:.0%} or more", models)
                if self.p.oblique and len(specs[j].variables) == 1 \
                        and specs[j].switch != "continuous":  # already hinged
                    current = self.hinge(group, j, specs, models, coupling, current)
                path.append((dict(specs), dict(models)))
        return path

    def try_spec(self, group: list[int], j: int, specs: dict, models: dict,
                 spec: OutputSpec, coupling: str) -> tuple[float, dict, dict] | None:
        """Output j's least-squares model of ``spec`` beside the group's others, measured:
        (held-out NRMSE, models, specs), or None (recorded as skipped) when one of its
        regions holds too few training rows."""
        trial = {**models, j: self.model(j, spec, coupling)}
        tried = {**specs, j: spec}
        if not self.enough_rows(trial[j]):
            self.record("scheduled", group, tried, np.nan,
                        "skipped: a region holds too few training rows")
            return None
        return self.measure(trial, group), trial, tried

    def hinge(self, group: list[int], j: int, specs: dict, models: dict, coupling: str,
              current: float) -> float:
        """Breiman's hinge finding on output j's one boundary: two affine pieces of a
        continuous map meet where θ₁ᵀφ = θ₀ᵀφ, so the boundary is moved there
        (w ← θ₁ − θ₀ over φ) and both pieces refitted, while the held-out NRMSE falls by
        ``min_gain`` (at most `HINGE_STEPS` times). A discontinuous switch (a
        friction offset) gains nothing and keeps its boundary. Updates ``specs[j]`` and
        ``models[j]`` in place; returns the held-out NRMSE."""
        for _ in range(HINGE_STEPS):
            if self.stopped():
                break
            thetas = models[j].thetas()
            w = thetas[1] - thetas[0]
            if not np.any(w[:-1]):
                break
            if w[np.argmax(np.abs(w[:-1]))] < 0:  # either side may be region 1: read w > 0
                w = -w
            var = Variable(f"hinge of y{j + 1}: {oblique_name(w, self.names)}", w)
            spec = replace(specs[j], variables=(var,))
            measured = self.try_spec(group, j, specs, models, spec, coupling)
            if measured is None:
                break
            cost, trial, tried = measured
            better = bool(np.isfinite(cost)) and cost < current * (1 - self.p.min_gain)
            self.record("scheduled", group, tried, cost,
                        f"kept for y{j + 1}: the hinge of its two pieces" if better
                        else "hinge tried: not better", trial)
            if not better:
                break
            current, specs[j], models[j] = cost, spec, trial[j]
        return current

    def clustered_stage(self, group: list[int], specs: dict, coupling: str
                        ) -> list[tuple[dict, dict]]:
        """The paper's clustered regions on the group's regressors (those of its linear
        reference): a candidate beside the scheduled ones, or none."""
        if not self.p.clustering or self.cluster is None or self.stopped():
            return []
        base = specs[group[0]]
        spec = OutputSpec(base.form, base.na, base.nb, switch="clustered")
        parts = {j: output_regressors(j, self.m, self.r, spec.na, spec.nb, True, spec.form,
                                      coupling, phi_lags=self.lags, phi_nb=self.nb)
                 for j in group}
        tried = dict.fromkeys(group, spec)
        try:
            trial = clustered_models(group, self.reg, parts, self.cluster)
        except (ValueError, np.linalg.LinAlgError) as exc:
            self.record("clustered", group, tried, np.nan, f"skipped: {exc}")
            return []
        s = trial[group[0]].n_regions
        cost = self.measure(trial, group)
        useful = bool(np.isfinite(cost)) and s > 1
        self.record("clustered", group, tried, cost,
                    "candidate: refined next" if useful else
                    ("one cluster: the linear model" if s == 1 else "diverged"), trial)
        return [(tried, trial)] if useful else []

    def runner_up(self, group: list[int], first: float) -> str:
        """The best switching candidate the group's linear model beat, in a sentence (or
        that none was measured); ``first``: the refined linear model's held-out NRMSE on
        the first fold."""
        def switching(stages):
            return [r for r in self.rows if r["outputs"] == _outputs(group)
                    and r["stage"] in stages
                    and not all(part.endswith("linear") for part in r["structure"].split("; "))
                    and np.isfinite(r["validation_nrmse"])]

        # judged as the linear model was: over the folds when there are several
        rows = switching(("cross-validated",))
        if rows:
            best = min(rows, key=lambda r: r["validation_nrmse"])
            return (f" The best switching candidate measured, {best['structure']}, had "
                    f"{best['validation_nrmse']:#.4g}{self.over_folds()}.")
        rows = switching(("scheduled", "clustered", "refined"))
        if not rows:
            reason = self.stop_reason().removeprefix("; ")
            return " No switching candidate was measured" + (f" ({reason})." if reason
                                                            else ".")
        best = min(rows, key=lambda r: r["validation_nrmse"])
        where = "" if len(self.folds) == 1 else (
            f" on the first held-out block, where the refined linear model had {first:#.4g} "
            f"(none lowered the error by min_gain, so none was judged on every fold)")
        return (f" The best switching candidate measured, {best['structure']}, had "
                f"{best['validation_nrmse']:#.4g}{where}.")

    def default_stage(self, final: float) -> tuple[float, dict, str] | None:
        """The library default [`PWARX`][pwa_pipeline.PWARX] of the largest orders (level form,
        joint outputs, the paper's steps 2–6 on eq. (3)'s φ) fitted on the fitting
        experiments, and the same with the constant by the search's own clustering steps
        (``cluster``: the default's with at most 3 re-assignment sweeps and no search for
        missed modes, which on EMPS's 20,000 rows with a constant took 164 s): the
        search's result is never worse on the held-out experiments than the model a user
        gets without it. Measured whatever the budget (as the linear stage); returns
        (held-out NRMSE, models by output, structure in words) of the better one when it
        beats ``final``, else None."""
        if not self.p.clustering or self.default is None or self.cluster is None \
                or self.late():
            return None
        _log.info(f"structure search: the default PWARX of orders ({self.na}, {self.nb}) "
                  f"({self.elapsed()})")
        group = list(range(self.m))
        best = None
        for affine in (False, True):
            spec = OutputSpec("level", self.na, self.nb, switch="clustered")
            label = "default PWARX" + (" with a constant" if affine else "")
            tried = dict.fromkeys(group, spec)
            parts = {}
            for j in group:
                M, c, names = output_regressors(j, self.m, self.r, self.na, self.nb, True,
                                                "level", "joint", phi_lags=self.lags,
                                                phi_nb=self.nb)
                parts[j] = (M, c, names) if affine else (M[:-1], c, names[:-1])
            try:
                trial = clustered_models(group, self.reg, parts,
                                         self.cluster if affine else self.default)
            except (ValueError, np.linalg.LinAlgError) as exc:
                self.record("default", group, tried, np.nan, f"{label}: skipped: {exc}")
                continue
            trial = self.on_all_rows(group, trial)
            cost = self.measure(trial, group)
            if len(self.folds) > 1 and np.isfinite(cost):
                costs = self.cross_validated(group, trial, cost, refine=False)
                cost = float(np.mean(costs)) if np.all(np.isfinite(costs)) else np.inf
            s = trial[0].n_regions
            text = (f"level ({self.na}, {self.nb}){' with a constant' if affine else ''}, "
                    f"clustered ({s} regions)")
            better = bool(cost < final) and (best is None or cost < best[0])
            self.record("default", group, tried, cost,
                        f"{label}: " + ("beats the search's choice" if cost < final
                                        else "not better than the search's choice"), trial)
            if better:
                best = (cost, trial, text)
        if best is not None:
            for row in self.rows:  # one chosen row: the search's own choice is superseded
                if row["stage"] == "chosen":
                    row["stage"] = "searched"
                    row["outcome"] = "superseded by the default PWARX: " + row["outcome"]
            self.record("chosen", group, dict.fromkeys(
                group, OutputSpec("level", self.na, self.nb, switch="clustered")), best[0],
                "chosen: the default PWARX, better than the search's structures on the "
                "held-out experiments", best[1])
        return best

    def refined(self, group: list[int], specs: dict, models: dict, label: str):
        """The group's models refined on the free-run error (as given without a
        refinement); returns (held-out NRMSE, models, refinement info)."""
        if self.p.refinement_step() is None:
            return self.cost(models, group), models, {}
        if self.late():
            cost0 = self.cost(models, group)
            self.record("refined", group, specs, cost0, "not refined: time limit reached",
                        models)
            return cost0, models, {}
        cost, models, res, note = self.refine_on(self.folds[0], group, models)
        self.record("refined", group, specs, cost,
                    f"not refined: {note}" if res is None else f"refined ({res.stop})", models)
        if res is None:
            return cost, models, {}
        info = {"outputs": group, "structure": label, "seconds": res.seconds,
                "n_iter": res.n_iter, "stop": res.stop, "cost_start": res.cost_start,
                "cost": res.cost, "one_step_start": res.one_step_start,
                "one_step": res.one_step_cost}
        return cost, models, info

    def refine_on(self, fold: "_Fold", group: list[int], models: dict):
        """Copies of the group's models refined on one fold's fitting experiments (to the
        refinement's tolerance or ``max_iter``; the start kept when better on the held-out
        block): (held-out NRMSE, models, the refinement's result or None, why not
        refined)."""
        step = self.p.refinement_step()
        models = {j: replace_p(models[j]) for j in group}
        cost0 = fold.cost(models, group)
        remaining = max(1.0, self.p.max_seconds - (time.perf_counter() - self.t0))
        try:
            res = refine_outputs(models, group, fold.u, fold.y, self.lags, self.nb, True,
                                 self.warmup, max_iter=step.max_iter,
                                 max_seconds=min(step.max_seconds, remaining), tol=step.tol,
                                 one_step_weight=step.one_step_weight, limits=self.limits)
        except ValueError as exc:
            return cost0, models, None, str(exc)
        start = {j: models[j].p for j in group}
        assign_params(models, group, res.thetas)
        cost = fold.cost(models, group)
        if not cost <= cost0:  # refined on J_w of the fitting part; keep the start if better
            for j in group:
                models[j].p = start[j]
            cost = cost0
        return cost, models, res, ""

    def cross_validated(self, group: list[int], models: dict, main: float, refine: bool
                        ) -> list[float]:
        """A candidate's held-out NRMSE on every fold: ``main`` on the first (measured
        already), and on each other fold its least-squares models (``models``: the regions
        kept, as functions of φ) fitted again on the fold's fitting blocks and, when
        ``refine``, refined as on the first."""
        costs = [main]
        for fold in self.folds[1:]:
            fitted = {j: replace_p(models[j]).fit(fold.reg.phi, fold.reg.target[:, j])
                      for j in group}
            if refine and self.p.refinement_step() is not None and not self.late():
                costs.append(self.refine_on(fold, group, fitted)[0])
            else:
                costs.append(fold.cost(fitted, group))
        return costs

    def refit(self, groups: list[list[int]], chosen: dict[int, OutputModel]
              ) -> dict[int, OutputModel]:
        """The chosen structure fitted again on every training experiment, held-out ones
        included: least squares in the chosen regions, then the refinement (no iterate to
        choose now: it stops by its tolerance or ``max_iter``). A group whose refit free
        run diverges keeps the models fitted without the held-out experiments."""
        experiments = self.fit_exp + self.held_exp
        reg = build_regressors(experiments, self.lags, self.nb, True)
        u, y = [e[0] for e in experiments], [e[1] for e in experiments]
        step = self.p.refinement_step()
        out = dict(chosen)
        for group in groups:
            remaining = max(1.0, self.p.max_seconds - (time.perf_counter() - self.t0))
            models = {j: replace_p(chosen[j]).fit(reg.phi, reg.target[:, j]) for j in group}
            if step is not None:
                try:
                    res = refine_outputs(models, group, u, y, self.lags, self.nb, True,
                                         self.warmup, max_iter=step.max_iter,
                                         max_seconds=min(step.max_seconds, remaining),
                                         tol=step.tol,
                                         one_step_weight=step.one_step_weight,
                                         limits=self.limits)
                except ValueError as exc:
                    self.rows.append({"stage": "refit", "outputs": _outputs(group),
                                      "outcome": f"kept as fitted without the held-out "
                                                 f"experiments: {exc}",
                                      "seconds": round(time.perf_counter() - self.t0, 3)})
                    continue
                assign_params(models, group, res.thetas)
            out.update(models)
        return out


def oblique_name(w: np.ndarray, names: list[str], terms: int = 4) -> str:
    """An oblique boundary wᵀφ > 0 in words, scaled so that its largest coefficient is ±1,
    the constant moved to the right and the ``terms`` largest entries shown, e.g.
    ``"y1(k-1) + 0.625·u1(k-1) > 1.25"``."""
    coef, constant = w[:-1], w[-1]
    scale = np.max(np.abs(coef))
    if scale == 0:
        return f"{constant:.4g} > 0"
    coef, constant = coef / scale, constant / scale
    order = [i for i in np.argsort(-np.abs(coef), kind="stable") if coef[i] != 0][:terms]
    text = ""
    for n, i in enumerate(order):
        c = coef[i]
        sign = ("-" if c < 0 else "") if n == 0 else (" - " if c < 0 else " + ")
        size = "" if np.isclose(abs(c), 1) else f"{abs(c):.3g}·"
        text += f"{sign}{size}{names[i]}"
    if np.count_nonzero(coef) > terms:
        text += " + …"
    return f"{text} > {-constant:.4g}"


def _outputs(group: list[int]) -> str:
    """E.g. ``"y1, y2"``."""
    return ", ".join(f"y{j + 1}" for j in group)


def replace_p(om: OutputModel) -> OutputModel:
    """A copy of an output model with its own parameter vector (the refinement sets it)."""
    return replace(om, p=om.p.copy())
