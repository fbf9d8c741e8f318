"""The PWARX estimator: MIMO piecewise-affine ARX identification by extended DBSCAN."""

import time
from numbers import Integral

import numpy as np
from sklearn.base import BaseEstimator, _fit_context, clone
from sklearn.utils._param_validation import HasMethods, Interval, StrOptions
from sklearn.utils.validation import check_is_fitted

from .._typing import Signals
from .._validation import as_experiments
from ..envelope import training_range
from ..regressors import Regressors, build_regressors
from .arx import ARXModelBase
from .divergence import warn_if_diverging
from .groups import OutputGroup
from .limits import MEASURED, bounds, describe, has_limits, resolve_limits
from .memory import check_fit_memory
from .search import StructureSearch
from .steps.boundaries import ResidualRegions
from .steps.clustering import DBSCANClustering
from .steps.local_models import LocalLeastSquares
from .steps.regions import SVMRegions
from .steps.submodels import ClusterCentres, RefinedSubModels, output_lag_columns
from .structure_fit import fit_structure
from .structures import COUPLINGS, FORMS, output_groups

#: The step parameters of `PWARX`, in the order the fit runs them.
STEPS = ("local_models", "clustering", "submodels", "regions")


class PWARX(ARXModelBase):
    """MIMO piecewise-affine ARX model identified by clustering local models (Lassoued &
    Abderrahim 2023).

    y(k) = θ_iᵀ φ(k) when φ(k) ∈ H_i (eq. 1), φ(k) from eq. (2)–(3). The fit runs the
    paper's steps, each an estimator object with its own parameters (in the manner of
    pysindy's ``optimizer=``): regressors (eq. 2–3), then ``local_models`` (local sets of n_ρ
    neighbours and local least squares, eq. 6–7), ``clustering`` (DBSCAN on the Vθ distance,
    eq. 8–10), ``submodels`` (one θ_i per cluster, step 5) and ``regions`` (the H_i by a
    multi-class linear SVM, step 6). The steps are cloned at fit; every choice is a parameter,
    visible in ``get_params(deep=True)`` (e.g. ``clustering__eps``) and settable by
    ``set_params``.

    The library default (``PWARX()``, the same as [`PWARX.default`][pwa_pipeline.PWARX.default]) differs from
    the paper where measurement showed the paper's version fails (``shared/paper/NOTES.md``):
    z-scored neighbour search and at most 5,000 local models estimated
    ([`LocalLeastSquares`][pwa_pipeline.pwa.LocalLeastSquares]), unit-free θ_k,
    mixed local sets left out and at most 3,000 local models clustered, ε from the k-distance
    curve ([`DBSCANClustering`][pwa_pipeline.pwa.DBSCANClustering]), and sub-models refitted, merged,
    re-assigned by residual and region, with a search for missed modes
    ([`RefinedSubModels`][pwa_pipeline.pwa.RefinedSubModels]), and region boundaries refined on the
    residuals ([`ResidualRegions`][pwa_pipeline.pwa.ResidualRegions]).
    [`PWARX.paper`][pwa_pipeline.PWARX.paper] is the paper's setting.

    Each step object implements the interface of its kind (`steps.base`:
    [`BaseLocalModels`][pwa_pipeline.pwa.steps.base.BaseLocalModels],
    [`BaseClustering`][pwa_pipeline.pwa.steps.base.BaseClustering],
    [`BaseSubModels`][pwa_pipeline.pwa.steps.base.BaseSubModels],
    [`BaseRegions`][pwa_pipeline.pwa.steps.base.BaseRegions]): a step of one's own is one class of that kind,
    e.g. a region learner implements ``fit``, ``predict`` and ``halfspaces`` and then predicts, simulates and
    exports to state space as the built-in ones do.

    ``form="velocity"``, ``outputs="decoupled"`` and ``scheduling`` give the structures of
    `structure_fit` (the paper's steps run per output group on its regressor ψ when
    ``scheduling`` is None); ``search`` ([`auto`][pwa_pipeline.PWARX.auto]) the structure search of
    `search`. Every combination ends in the same fitted shape: output groups, each
    with one region map and its sub-models (`groups`), and from them ``thetas_``,
    ``regions_``, ``n_submodels_``, `predict`, `simulate` and
    `to_state_space`.

    Parameters
    ----------
    na, nb : int
        Output and input orders (eq. 3).
    affine : bool, default False
        Append the constant 1 to φ (eq. 2).
    local_models : estimator, optional
        Steps 2–3. None: ``LocalLeastSquares()``.
    clustering : estimator, optional
        Step 4. None: ``DBSCANClustering()``.
    submodels : estimator, optional
        Step 5. None: ``RefinedSubModels()``; the paper's is ``ClusterCentres()``.
    regions : estimator, optional
        Step 6. None: ``ResidualRegions()`` (the SVM's regions with boundaries moved to
        where the sub-models' residuals switch); the paper's is ``SVMRegions()``.
    refinement : estimator, optional
        After step 6, an `OutputErrorRefinement`: the θ_i refined to
        minimise the free-run error on the training experiments, the regions kept. None (the
        paper's route and the default): no refinement.
    form : {"level", "velocity"}, default "level"
        ``"velocity"``: each output's increment Δy(k) from na lagged increments, the level
        y(k−1) and the inputs, integrated in simulation (`structures`).
    outputs : {"joint", "decoupled"}, default "joint"
        ``"decoupled"``: one MISO model per output, on its own lags and every input, with
        its own regions.
    scheduling : SignScheduling, optional
        Regions given by the user (`SignScheduling`, e.g. the sign of
        each output's increment), in place of steps 2–6; sub-models by least squares per
        region, optionally a structure chosen per output on held-out training experiments.
    search : StructureSearch, optional
        The structure chosen from the data ([`StructureSearch`][pwa_pipeline.pwa.StructureSearch],
        built by [`auto`][pwa_pipeline.PWARX.auto]): form, coupling, regions (scheduling variables it
        proposes, or the steps' clusters), modes and orders up to ``na``, ``nb``, judged on held-out
        training experiments and refined; never worse there than its linear reference.
        Needs ``affine=True`` and leaves ``form``, ``outputs``, ``scheduling`` and
        ``refinement`` to the search.
    output_limits : "measured", array-like of shape (2, m) or None, default None
        Levels the outputs saturate at (`limits`): ŷ_j is clipped to
        [lo_j, hi_j] in prediction, in simulation and in every free run the fit measures or
        refines, still a PWA model (each region split by Θ_iᵀφ = lo_j, hi_j;
        `to_state_space` exports the parts). ``"measured"``: the extremes a training
        experiment holds for several samples in a row (a sensor's range, a tank's rim);
        given: lower limits, then upper ones, NaN where an output has none. None: no limits.
        [`auto`][pwa_pipeline.PWARX.auto] sets ``"measured"``.

    Attributes
    ----------
    groups_ : list of OutputGroup
        The fitted model ([`OutputGroup`][pwa_pipeline.pwa.OutputGroup]): outputs that switch together,
        their region map over φ and each region's parameter rows, with the fitted steps
        that found them (``group.steps``: ``local_models``, ``clustering``, ``submodels``,
        ``regions`` and ``refinement`` where they ran). The paper's route is one group.
    thetas_ : ndarray of shape (s, d, m)
        Sub-model parameter matrices θ_i (eq. 4) of the model as eq. (1): on the paper's
        route refitted with the regions by the default's step 6
        ([`ResidualRegions`][pwa_pipeline.pwa.ResidualRegions]) and refined when ``refinement`` is
        given (``groups_[0].steps["submodels"].thetas_`` keeps step 5's); with several output
        groups one per combination of their regions.
    regions_ : RegionMap
        ``regions_.predict(phi)`` gives the sub-model of each regressor row (the paper's
        route: the fitted region step).
    n_submodels_ : int
        s.
    structures_ : list of str
        Each output's structure in words: form, orders and regions.
    n_inputs_, n_outputs_ : int
    timings_ : dict
        Seconds spent in each stage of the fit (the paper's steps by name, or the
        structured fit, or the search): their sum is the fit's time.
    structure_fit_ : StructureFit (structured fits and the search)
        The held-out experiments, each candidate's validation error, the refinements.
    structure_search_ : SearchReport
        With ``search`` only: every candidate the search tried, its held-out free-run NRMSE
        and outcome, and why it chose ([`SearchReport`][pwa_pipeline.pwa.SearchReport]).
    output_limits_ : ndarray of shape (2, m)
        The outputs' lower and upper limits in use, ±inf where none.
    signal_range_ : ndarray of shape (2, m + r)
        Smallest and largest training value of each output, then each input: the data
        envelope of `outside_envelope` and of
        `to_state_space`.

    Examples
    --------
    >>> import numpy as np
    >>> from pwa_pipeline import PWARX, make_hure_vasak
    >>> data = make_hure_vasak(n_samples=2000, snr_db=None, seed=0)
    >>> model = PWARX(na=1, nb=1).fit(data.u_train, data.y_train)
    >>> model.n_submodels_
    4
    >>> bool(np.allclose(np.sort(model.thetas_, axis=0), np.sort(data.truth.thetas, axis=0)))
    True
    >>> PWARX.default(na=1, nb=1).set_params(clustering__eps=0.2).get_params()["clustering__eps"]
    0.2
    """

    _parameter_constraints: dict = {
        "na": [Interval(Integral, 0, None, closed="left")],
        "nb": [Interval(Integral, 0, None, closed="left")],
        "affine": ["boolean"],
        "local_models": [HasMethods(["fit"]), None],
        "clustering": [HasMethods(["fit"]), None],
        "submodels": [HasMethods(["fit"]), None],
        "regions": [HasMethods(["fit", "predict"]), None],
        "refinement": [HasMethods(["fit"]), None],
        "form": [StrOptions(set(FORMS))],
        "outputs": [StrOptions(set(COUPLINGS))],
        "scheduling": [HasMethods(["weights"]), None],
        "search": [HasMethods(["search"]), None],
        "output_limits": [StrOptions({MEASURED}), "array-like", None],
    }

    def __init__(
        self,
        na: int = 1,
        nb: int = 1,
        affine: bool = False,
        local_models: BaseEstimator | None = None,
        clustering: BaseEstimator | None = None,
        submodels: BaseEstimator | None = None,
        regions: BaseEstimator | None = None,
        refinement: BaseEstimator | None = None,
        form: str = "level",
        outputs: str = "joint",
        scheduling: BaseEstimator | None = None,
        search: BaseEstimator | None = None,
        output_limits: str | np.ndarray | None = None,
    ):
        self.na = na
        self.nb = nb
        self.affine = affine
        self.local_models = local_models
        self.clustering = clustering
        self.submodels = submodels
        self.regions = regions
        self.refinement = refinement
        self.form = form
        self.outputs = outputs
        self.scheduling = scheduling
        self.search = search
        self.output_limits = output_limits

    @classmethod
    def default(cls, na: int = 1, nb: int = 1, affine: bool = False) -> "PWARX":
        """The library default with every step object spelled out (so that
        ``get_params(deep=True)`` lists each step's parameters); it fits like ``PWARX()``."""
        return cls(na=na, nb=nb, affine=affine, local_models=LocalLeastSquares(),
                   clustering=DBSCANClustering(), submodels=RefinedSubModels(),
                   regions=ResidualRegions())

    @classmethod
    def auto(cls, na: int = 2, nb: int = 2, **search: object) -> "PWARX":
        """The structure chosen from the data (`search`): forms, joint or
        per-output models, regions from scheduling variables the search proposes or from
        the paper's clustering, modes per output and orders up to (``na``, ``nb``), each
        judged by its free run on held-out training experiments, refined on the free-run
        error; never worse there than the best linear ARX model it also fits (which it then
        returns, and says so in ``structure_search_``). The outputs' measured limits
        (``output_limits="measured"``, `limits`) clip every candidate.

        The clustered candidate runs the default's steps with at most 3 re-assignment
        sweeps of the sub-models and no search for missed modes (``submodels__n_refine``,
        ``submodels__n_search``): on the robot's per-joint regressors the default's 20
        sweeps and 3 searches cost minutes of SVM fits, and on the tuning machines they
        gave the same held-out error.

        Parameters
        ----------
        na, nb : int, default 2
            The largest orders tried.
        **search
            Parameters of [`StructureSearch`][pwa_pipeline.pwa.StructureSearch] (e.g.
            ``max_candidates=500``).
        """
        return cls(na=na, nb=nb, affine=True,
                   submodels=RefinedSubModels(n_refine=3, n_search=0),
                   search=StructureSearch(**search), output_limits=MEASURED)

    @classmethod
    def paper(cls, na: int, nb: int, *, n_rho: int, eps: float, min_pts: int,
              affine: bool = False) -> "PWARX":
        """The paper's setting: raw regressors in the neighbour search, a local model for
        every sample, DBSCAN on θ_k as it is with every local model, sub-models as cluster
        centres, the SVM trained on every clustered row (noise left out; solver tolerance
        1e-2, see [`SVMRegions`][pwa_pipeline.pwa.SVMRegions]).

        The paper gives n_ρ, ε and MinPts per data set and no rule, so they are required;
        its values are in ``data/hparams.toml`` (sets ``paper``).
        """
        return cls(na=na, nb=nb, affine=affine,
                   local_models=LocalLeastSquares(n_rho=n_rho, standardize=False,
                                                  max_sets=None),
                   clustering=DBSCANClustering(eps=eps, min_pts=min_pts, unit_free=False,
                                               confidence=None, max_clustered=None),
                   submodels=ClusterCentres(), regions=SVMRegions(max_rows=None, tol=1e-2))

    def step_objects(self) -> dict[str, BaseEstimator]:
        """The unfitted step objects, defaults filled in for those left None."""
        return {name: getattr(self, name) if getattr(self, name) is not None
                else _DEFAULT_STEPS[name]() for name in STEPS}

    def set_params(self, **params) -> "PWARX":
        """Set parameters, the steps' own by ``<step>__<parameter>`` (e.g.
        ``clustering__eps``), as scikit-learn's ``set_params``; a step left at its default
        (None) becomes the default step object first, so every documented step parameter is
        settable on a plain ``PWARX(...)``.

        Raises
        ------
        ValueError
            For a parameter of ``refinement``, ``scheduling`` or ``search`` while that
            option is None (off): give the option's object first.
        """
        for name in STEPS:
            if getattr(self, name) is None and name not in params \
                    and any(key.startswith(f"{name}__") for key in params):
                setattr(self, name, _DEFAULT_STEPS[name]())
        for name in ("refinement", "scheduling", "search"):
            nested = [key for key in params if key.startswith(f"{name}__")]
            if nested and getattr(self, name) is None and params.get(name) is None:
                raise ValueError(f"{nested[0]}: {name} is None (off); set {name}= to its "
                                 f"object first, e.g. {_OPTION_EXAMPLES[name]}")
        return super().set_params(**params)

    @_fit_context(prefer_skip_nested_validation=True)
    def fit(self, u: Signals, y: Signals) -> "PWARX":
        """Identify the PWARX model from one or several experiments.

        Every parameter combination ends in the same fitted shape (`groups`): the
        paper's steps on φ give one output group; ``form``, ``outputs`` or ``scheduling``
        give the structures of `structure_fit`; ``search`` the structure search of
        `search`.

        Parameters
        ----------
        u : array-like of shape (N, r), or a list of such arrays (separate experiments)
        y : array-like of shape (N, m), or a list of such arrays

        Returns
        -------
        self

        Raises
        ------
        ValueError
            On NaN/inf, mismatched lengths or dimensions, too few samples for n_ρ, n_ρ ≤ d,
            too few usable (non-degenerate) local sets to cluster, when DBSCAN finds no
            cluster, or for options that do not go together (named in the message).
        pwa_pipeline.pwa.memory.FitMemoryError
            At once, before any step, when the fit's estimated memory exceeds what the
            machine has available (`check_fit_memory`); the
            message gives the estimate and the setting to change.

        Warns
        -----
        pwa_pipeline.pwa.DivergenceWarning
            On the paper's route, when the fitted model's free run on the training
            experiments diverges (`warn_if_diverging`), naming what to try.
        """
        experiments = as_experiments(u, y)
        self.output_limits_ = resolve_limits(self.output_limits, [e[1] for e in experiments])
        self.signal_range_ = training_range(experiments)
        self.n_inputs_ = experiments[0][0].shape[1]
        self.n_outputs_ = experiments[0][1].shape[1]
        self.n_features_in_ = self.n_inputs_
        self.timings_ = {}
        if self.search is not None:
            self.groups_, self.structures_ = self._fit_search(experiments)
        elif self.form != "level" or self.outputs != "joint" or self.scheduling is not None:
            self.groups_, self.structures_ = self._fit_structure(experiments)
        else:
            self.groups_, self.structures_ = self._fit_steps(experiments)
            warn_if_diverging(self, experiments)
        self.structures_ = [text + describe(self.output_limits_, j, f"y{j + 1}")
                            for j, text in enumerate(self.structures_)]
        return self

    def _limits(self) -> np.ndarray | None:
        """``output_limits_`` when some output has a limit, else None (nothing to clip)."""
        return self.output_limits_ if has_limits(self.output_limits_) else None

    @property
    def output_lags_(self) -> int:
        """Output lags of φ: na, or na + 1 in the velocity form or with a structure search
        (whose na is the largest order it tries, in either form)."""
        return self.na + 1 if self.search is not None else super().output_lags_

    def _run_steps(self, reg: Regressors, eq3: bool, timings: dict | None = None
                   ) -> tuple[np.ndarray, dict]:
        """The paper's steps 2–6 on the regressors ``reg``: θ_i (s, d, m) and the fitted
        steps by name, each step's seconds put in ``timings`` when given. ``eq3``: ``reg``
        holds eq. (3)'s φ (the region step then gets its output-lag columns and each row's
        experiment; an output group's ψ has neither)."""
        steps = self.step_objects()
        check_fit_memory(*reg.phi.shape, reg.target.shape[1], steps,
                         base=reg.phi.nbytes + reg.target.nbytes)
        fitted: dict[str, BaseEstimator] = {}

        def timed(name: str, fit) -> BaseEstimator:
            t0 = time.perf_counter()
            fitted[name] = fit(clone(steps[name]))
            if timings is not None:
                timings[name] = time.perf_counter() - t0
            return fitted[name]

        local = timed("local_models", lambda s: s.fit(reg.phi, reg.target))
        clusters = timed("clustering", lambda s: s.fit(local, reg.target))
        subs = timed("submodels", lambda s: s.fit(reg.phi, reg.target, local, clusters,
                                                  regions=steps["regions"]))
        lags = output_lag_columns(reg.n_outputs, self.na, reg.phi.shape[1]) if eq3 else None
        regions = timed("regions", lambda s: s.fit(
            reg.phi, subs.labels_, subs.n_submodels_, sample_weight=subs.weights_,
            target=reg.target, thetas=subs.thetas_, output_lags=lags,
            experiment=reg.experiment if eq3 else None))
        # the region step may refit the sub-models with its regions (ResidualRegions)
        thetas = getattr(regions, "thetas_", subs.thetas_)
        if regions.n_regions_ != len(thetas):
            raise ValueError(f"the region step {type(regions).__name__} has "
                             f"{regions.n_regions_} regions for {len(thetas)} sub-models; a "
                             f"region step has one region per sub-model (fit's n_regions)")
        return thetas, fitted

    def _fit_steps(self, experiments: list) -> tuple[list[OutputGroup], list[str]]:
        """The paper's route: steps 2–6 on φ, one output group, refined on request."""
        t0 = time.perf_counter()
        reg = build_regressors(experiments, self.na, self.nb, self.affine)
        self.timings_["regressors"] = time.perf_counter() - t0
        thetas, steps = self._run_steps(reg, eq3=True, timings=self.timings_)
        if self.refinement is not None:
            t0 = time.perf_counter()
            steps["refinement"] = clone(self.refinement).fit(
                thetas, [e[0] for e in experiments], [e[1] for e in experiments], self.na,
                self.nb, self.affine, region_of=steps["regions"].predict,
                limits=self._limits())
            thetas = steps["refinement"].thetas_
            self.timings_["refinement"] = time.perf_counter() - t0
        group = OutputGroup(tuple(range(reg.n_outputs)), steps["regions"], thetas, steps,
                            self._limits())
        kind = f"clustered ({group.n_regions} regions)" if group.n_regions > 1 else \
            "clustered (1 region: linear)"
        return [group], [f"level ({self.na}, {self.nb}), {kind}"] * reg.n_outputs

    def _cluster(self, reg: Regressors) -> tuple[np.ndarray, dict]:
        """The paper's steps 2–6 on an output group's regressors ψ (the structured routes'
        clustered candidates)."""
        return self._run_steps(reg, eq3=False)

    def _fit_structure(self, experiments: list) -> tuple[list[OutputGroup], list[str]]:
        """The structures of `structure_fit` (velocity form, one model per output,
        user regions)."""
        t0 = time.perf_counter()
        self.structure_fit_ = fit_structure(
            experiments, self.na, self.nb, self.affine, self.form, self.outputs,
            scheduling=self.scheduling, refinement=self.refinement,
            cluster=self._cluster if self.scheduling is None else None,
            limits=self._limits())
        self.timings_["structure"] = time.perf_counter() - t0
        outputs = self.structure_fit_.outputs
        described = [f"{self.form} ({self.na}, {self.nb}), {o.structure}{o.size()}"
                     for o in outputs]
        return output_groups(outputs, self._limits()), described

    def _fit_search(self, experiments: list) -> tuple[list[OutputGroup], list[str]]:
        """The structure search of `search` ([`auto`][pwa_pipeline.PWARX.auto])."""
        given = [name for name, default in (("form", "level"), ("outputs", "joint"))
                 if getattr(self, name) != default]
        given += [name for name in ("scheduling", "refinement")
                  if getattr(self, name) is not None]
        if given:
            raise ValueError(f"the structure search chooses the form, the outputs' "
                             f"coupling and the regions and refines them itself; leave "
                             f"{', '.join(given)} out (the search's own parameters set "
                             f"what it tries)")
        if not self.affine:
            raise ValueError("the structure search fits a constant term and proposes "
                             "thresholds on it: it needs affine=True (PWARX.auto sets it)")
        t0 = time.perf_counter()
        default = PWARX.default(self.na, self.nb)
        self.structure_fit_, self.structure_search_ = self.search.search(
            experiments, self.na, self.nb, cluster=self._cluster,
            default=lambda reg: default._run_steps(reg, eq3=True), limits=self._limits())
        self.timings_["search"] = time.perf_counter() - t0
        return output_groups(self.structure_fit_.outputs, self._limits()), list(
            self.structure_search_.structures)

    def resolved_params(self) -> dict:
        """Every parameter as ``get_params(deep=True)`` names it, with the values the fit
        chose filled in (n_ρ, ε, MinPts, from the fitted steps where they ran) and each
        output's structure (``structure_y1`` …); fitted models only. Caching handles
        (``memory``) are left out: they change no result."""
        check_is_fitted(self)
        out = {"na": self.na, "nb": self.nb, "affine": self.affine, "form": self.form,
               "outputs": self.outputs,
               "output_limits": "none" if self.output_limits is None else
               str(self.output_limits) if isinstance(self.output_limits, str) else "given"}
        named = {f"output_limits_y{j + 1}": bounds(self.output_limits_, j, f"y{j + 1}")
                 for j in range(self.n_outputs_)}
        out.update({key: text for key, text in named.items() if text})
        options = {"scheduling": self.scheduling, "search": self.search,
                   "refinement": self.refinement}
        for name, option in options.items():
            if option is not None:
                out[name] = type(option).__name__
                out.update({f"{name}__{k}": v for k, v in option.get_params().items()})
        fitted = next((g.steps for g in self.groups_ if g.steps), {})
        if self.scheduling is None:
            for name, step in self.step_objects().items():
                step = fitted.get(name, step)
                out[name] = type(step).__name__
                params = step.resolved_params() if name in fitted and hasattr(
                    step, "resolved_params") else step.get_params()
                out.update({f"{name}__{k}": v for k, v in params.items() if k != "memory"})
        out.update({f"structure_y{j + 1}": s for j, s in enumerate(self.structures_)})
        return out


#: The default step of each kind (`PWARX.step_objects`, `PWARX.set_params`).
_DEFAULT_STEPS = {"local_models": LocalLeastSquares, "clustering": DBSCANClustering,
                  "submodels": RefinedSubModels, "regions": ResidualRegions}
_OPTION_EXAMPLES = {"refinement": "refinement=OutputErrorRefinement()",
                    "scheduling": "scheduling=SignScheduling()",
                    "search": "search=StructureSearch() (or PWARX.auto)"}
