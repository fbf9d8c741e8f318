"""The PWARX estimator: MIMO piecewise-affine ARX identification by extended DBSCAN."""

import time
from numbers import Integral

import numpy as np
from sklearn.base import BaseEstimator, _fit_context, clone
from sklearn.utils._param_validation import HasMethods, Interval, StrOptions
from sklearn.utils.validation import check_is_fitted

from .._typing import Float2D, Signals
from .._validation import as_experiments
from ..envelope import PADDING
from ..regressors import Regressors, build_regressors
from .arx import ARXModelBase, training_range
from .memory import check_fit_memory
from .search.search import StructureSearch
from .steps.boundaries import ResidualRegions
from .steps.clustering import DBSCANClustering
from .steps.local_models import LocalLeastSquares
from .steps.regions import SVMRegions
from .steps.submodels import ClusterCentres, RefinedSubModels, output_lag_columns
from .structure_fit import fit_structure
from .structures import COUPLINGS, FORMS

#: The step parameters of :class:`PWARX`, in the order the fit runs them.
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

    The library default (``PWARX()``, the same as :meth:`PWARX.default`) differs from the
    paper where measurement showed the paper's version fails (``shared/paper/NOTES.md``):
    z-scored neighbour search and at most 5,000 local models estimated
    (:class:`~.local_models.LocalLeastSquares`), unit-free θ_k,
    mixed local sets left out and at most 3,000 local models clustered, ε from the k-distance
    curve (:class:`~.clustering.DBSCANClustering`), and sub-models refitted, merged,
    re-assigned by residual and region, with a search for missed modes
    (:class:`~.submodels.RefinedSubModels`), and region boundaries refined on the
    residuals (:class:`~.boundaries.ResidualRegions`). :meth:`PWARX.paper` is the paper's
    setting.

    Each step object implements the interface of its kind (:mod:`~.base`:
    :class:`~.base.BaseLocalModels`, :class:`~.base.BaseClustering`,
    :class:`~.base.BaseSubModels`, :class:`~.base.BaseRegions`), and :meth:`fit_step` calls
    every step of a kind alike.

    With ``form="velocity"``, ``outputs="decoupled"`` or ``scheduling``, the fit takes the
    structured route of :mod:`~.structure_fit` (the paper's steps run per output group on ψ
    when ``scheduling`` is None); with ``search`` (:meth:`auto`), the structure search of
    :mod:`~.structure_search`. The model is then ``structure_`` and ``thetas_``,
    ``regions_``, ``labels_`` and the fitted steps are not set.

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
        After step 6, an :class:`~.output_error.OutputErrorRefinement`: the θ_i refined to
        minimise the free-run error on the training experiments, the regions kept. None (the
        paper's route and the default): no refinement.
    form : {"level", "velocity"}, default "level"
        ``"velocity"``: each output's increment Δy(k) from na lagged increments, the level
        y(k−1) and the inputs, integrated in simulation (:mod:`~.structures`).
    outputs : {"joint", "decoupled"}, default "joint"
        ``"decoupled"``: one MISO model per output, on its own lags and every input, with
        its own regions.
    scheduling : SignScheduling, optional
        Regions given by the user (:class:`~.scheduling.SignScheduling`, e.g. the sign of
        each output's increment), in place of steps 2–6; sub-models by least squares per
        region, optionally a structure chosen per output on held-out training experiments.
    search : StructureSearch, optional
        The structure chosen from the data (:class:`~.structure_search.StructureSearch`,
        built by :meth:`auto`): form, coupling, regions (scheduling variables it proposes,
        or the steps' clusters), modes and orders up to ``na``, ``nb``, judged on held-out
        training experiments and refined; never worse there than its linear reference.
        Needs ``affine=True`` and leaves ``form``, ``outputs``, ``scheduling`` and
        ``refinement`` to the search.

    Attributes
    ----------
    local_models_, clustering_, submodels_, regions_ : fitted step estimators
        ``regions_.predict(phi)`` gives the region of each regressor row.
    refinement_ : fitted refinement step (with ``refinement`` only)
    thetas_ : ndarray of shape (s, d, m)
        Sub-model parameter matrices θ_i (eq. 4): refitted with the regions by the default's
        step 6 (:class:`~.boundaries.ResidualRegions`), refined when ``refinement`` is given
        (``submodels_.thetas_`` keeps step 5's, :meth:`base_thetas` those before the
        refinement).
    n_submodels_ : int
    labels_ : ndarray of shape (n,)
        Sub-model of each training regressor row (−1: DBSCAN noise, paper setting only).
    n_inputs_, n_outputs_ : int
    timings_ : dict
        Seconds spent in each step.
    structure_ : StructuredModel (structured route only)
        Per output its regressor, regions and sub-models (:mod:`~.structures`).
    structure_fit_ : StructureFit (structured route only)
        The held-out experiments, each candidate's validation error, the refinements.
    structure_search_ : SearchReport (with ``search`` only)
        Every candidate the search tried, its held-out free-run NRMSE and outcome, and
        why it chose (:class:`~.structure_search.SearchReport`).
    signal_range_ : ndarray of shape (2, m + r)
        Smallest and largest training value of each output, then each input (set by
        :meth:`fit`, or given to :meth:`assemble`; a model joined without it has none): the
        data envelope of :meth:`~.arx.ARXModelBase.outside_envelope` and of
        :meth:`to_state_space`.

    Examples
    --------
    >>> import numpy as np
    >>> from pwa_pipeline import PWARX, make_hure_vasak
    >>> data = make_hure_vasak(n_samples=2000, snr_db=None, seed=0)
    >>> model = PWARX(na=1, nb=1).fit(data.u, data.y)
    >>> model.n_submodels_
    4
    >>> bool(np.allclose(np.sort(model.thetas_, axis=0), np.sort(data.thetas, axis=0)))
    True
    >>> PWARX.default(na=1, nb=1).set_params(clustering__eps=0.2).get_params()["clustering__eps"]
    0.2
    """

    FIT_RECORD = ("local_models_", "clustering_", "submodels_", "labels_", "refinement_",
                  "structure_fit_", "structure_search_", "timings_")
    """Fitted attributes that record the fit (steps 2–5, the refinement, the rows' labels,
    the structure search, the seconds): ``predict`` and ``simulate`` use none of them
    (``thetas_`` and ``regions_``, or ``structure_``, make the model)."""

    FIT_PARAMS = (*STEPS, "refinement")
    """Parameters that only ``fit`` reads (the unfitted steps): ``predict`` and ``simulate``
    read what they fitted."""

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

    @classmethod
    def default(cls, na: int = 1, nb: int = 1, affine: bool = False) -> "PWARX":
        """The library default with every step object spelled out (so that
        ``get_params(deep=True)`` lists each step's parameters); it fits like ``PWARX()``."""
        return cls(na=na, nb=nb, affine=affine, local_models=LocalLeastSquares(),
                   clustering=DBSCANClustering(), submodels=RefinedSubModels(),
                   regions=ResidualRegions())

    @classmethod
    def auto(cls, na: int = 2, nb: int = 2, **search: object) -> "PWARX":
        """The structure chosen from the data (:mod:`~.structure_search`): forms, joint or
        per-output models, regions from scheduling variables the search proposes or from
        the paper's clustering, modes per output and orders up to (``na``, ``nb``), each
        judged by its free run on held-out training experiments, refined on the free-run
        error; never worse there than the best linear ARX model it also fits (which it then
        returns, and says so in ``structure_search_``).

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
            Parameters of :class:`~.structure_search.StructureSearch` (e.g.
            ``max_seconds=60``).
        """
        return cls(na=na, nb=nb, affine=True,
                   submodels=RefinedSubModels(n_refine=3, n_search=0),
                   search=StructureSearch(**search))

    @classmethod
    def paper(cls, na: int, nb: int, *, n_rho: int, eps: float, min_pts: int,
              affine: bool = False) -> "PWARX":
        """The paper's setting: raw regressors in the neighbour search, a local model for
        every sample, DBSCAN on θ_k as it is with every local model, sub-models as cluster
        centres, the SVM trained on every clustered row (noise left out; solver tolerance
        1e-2, see :class:`~pwa_pipeline.pwa.steps.regions.SVMRegions`).

        The paper gives n_ρ, ε and MinPts per data set and no rule, so they are required;
        its values are in ``data/hparams.toml`` (sets ``paper``).
        """
        return cls(na=na, nb=nb, affine=affine,
                   local_models=LocalLeastSquares(n_rho=n_rho, standardize=False,
                                                  max_sets=None),
                   clustering=DBSCANClustering(eps=eps, min_pts=min_pts, unit_free=False,
                                               confidence=None, max_clustered=None),
                   submodels=ClusterCentres(), regions=SVMRegions(max_rows=None, tol=1e-2))

    def steps(self) -> dict[str, BaseEstimator]:
        """The unfitted step objects, defaults filled in for those left None."""
        defaults = type(self).default()
        return {name: getattr(self, name) if getattr(self, name) is not None
                else getattr(defaults, name) for name in STEPS}

    @_fit_context(prefer_skip_nested_validation=True)
    def fit(self, u: Signals, y: Signals) -> "PWARX":
        """Identify the PWARX model from one or several experiments.

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
            too few usable (non-degenerate) local sets to cluster, or when DBSCAN finds no
            cluster.
        pwa_pipeline.pwa.memory.FitMemoryError
            At once, before any step, when the fit's estimated memory exceeds what the
            machine has available (:func:`~pwa_pipeline.pwa.memory.check_fit_memory`); the
            message gives the estimate and the setting to change.
        """
        timings: dict[str, float] = {}
        t0 = time.perf_counter()
        experiments = as_experiments(u, y)
        self.signal_range_ = training_range(experiments)
        if self.structured:
            return self._fit_structured(experiments)
        reg = build_regressors(experiments, self.na, self.nb, self.affine)
        timings["regressors"] = time.perf_counter() - t0
        fitted = {}
        for name in STEPS:
            t0 = time.perf_counter()
            fitted[name] = self.fit_step(name, reg, **fitted)
            timings[name] = time.perf_counter() - t0
        self.assemble(reg, **fitted, signal_range=self.signal_range_)
        if self.refinement is not None:
            t0 = time.perf_counter()
            self.assemble(reg, **fitted, refinement=self.fit_refinement(experiments),
                          signal_range=self.signal_range_)
            timings["refinement"] = time.perf_counter() - t0
        self.timings_ = timings
        return self

    @property
    def structured(self) -> bool:
        """Whether the fit takes the structured route (velocity form, decoupled outputs or
        user regions)."""
        return super().structured or self.scheduling is not None or self.search is not None

    @property
    def output_lags_(self) -> int:
        """Output lags of φ: na, or na + 1 in the velocity form or with a structure search
        (whose na is the largest order it tries, in either form)."""
        return self.na + 1 if self.search is not None else super().output_lags_

    def _fit_structured(self, experiments: list[tuple[Float2D, Float2D]]) -> "PWARX":
        t0 = time.perf_counter()

        def cluster(reg: Regressors):
            fitted: dict[str, BaseEstimator] = {}
            for name in STEPS:
                fitted[name] = self.fit_step(name, reg, **fitted)
            subs, regions = fitted["submodels"], fitted["regions"]
            return _base_thetas(subs, regions), regions, subs.n_submodels_

        if self.search is not None:
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
            self.structure_fit_, self.structure_search_ = self.search.search(
                experiments, self.na, self.nb, cluster=cluster)
        else:
            self.structure_fit_ = fit_structure(
                experiments, self.na, self.nb, self.affine, self.form, self.outputs,
                scheduling=self.scheduling, refinement=self.refinement,
                cluster=cluster if self.scheduling is None else None)
        self.structure_ = self.structure_fit_.model
        self.n_inputs_ = experiments[0][0].shape[1]
        self.n_outputs_ = experiments[0][1].shape[1]
        self.n_features_in_ = self.n_inputs_
        self.n_submodels_ = max(self.structure_.n_regions)
        self.timings_ = {"structure": time.perf_counter() - t0}
        return self

    def fit_refinement(self, experiments: list[tuple[Float2D, Float2D]]) -> BaseEstimator:
        """Fit a clone of ``refinement`` from the assembled model's θ_i and regions.

        Parameters
        ----------
        experiments : list of (u, y)
            The training experiments (:func:`~pwa_pipeline._validation.as_experiments`).

        Returns
        -------
        The fitted refinement step, for :meth:`assemble`.
        """
        return clone(self.refinement).fit(
            self.base_thetas(), [e[0] for e in experiments], [e[1] for e in experiments],
            self.na, self.nb, self.affine, region_of=self.regions_.predict)

    def base_thetas(self) -> np.ndarray:
        """The θ_i before any refinement (:func:`_base_thetas` of the fitted steps)."""
        return _base_thetas(self.submodels_, self.regions_)

    def fit_step(self, name: str, reg: Regressors, **fitted: BaseEstimator) -> BaseEstimator:
        """Fit a clone of the step ``name`` (one of :data:`STEPS`) on the regressors.

        Parameters
        ----------
        name : str
        reg : Regressors
            From :func:`~pwa_pipeline.regressors.build_regressors` with this model's
            orders.
        **fitted
            The steps before ``name``, fitted, by name (``local_models=...`` for
            ``clustering``; ``local_models`` and ``clustering`` for ``submodels``;
            ``submodels`` for ``regions``).

        Returns
        -------
        The fitted step. :meth:`fit` runs this for each step in turn; the pipeline runs it
        once per asset and joins the results with :meth:`assemble`.
        """
        steps = self.steps()
        step = clone(steps[name])
        if name == "local_models":  # the first step: fail now if the fit cannot fit in memory
            check_fit_memory(*reg.phi.shape, reg.target.shape[1], steps,
                             base=reg.phi.nbytes + reg.target.nbytes)
            return step.fit(reg.phi, reg.target)
        if name == "clustering":
            return step.fit(fitted["local_models"], reg.target)
        if name == "submodels":
            return step.fit(reg.phi, reg.target, fitted["local_models"], fitted["clustering"],
                            regions=steps["regions"])
        if name == "regions":
            subs = fitted["submodels"]
            # the output-lag columns of φ (eq. 3) and each row's experiment; the structured
            # route's regressors are not eq. (3)'s φ and pass neither
            output_lags = None if self.structured else output_lag_columns(
                reg.n_outputs, self.na, reg.phi.shape[1])
            return step.fit(reg.phi, subs.labels_, subs.n_submodels_,
                            sample_weight=subs.weights_, target=reg.target,
                            thetas=subs.thetas_, output_lags=output_lags,
                            experiment=None if self.structured else reg.experiment)
        raise ValueError(f"unknown step {name!r}; the steps are {list(STEPS)}")

    def assemble(self, reg: Regressors, local_models: BaseEstimator,
                 clustering: BaseEstimator, submodels: BaseEstimator,
                 regions: BaseEstimator, refinement: BaseEstimator | None = None, *,
                 signal_range: Float2D | None = None) -> "PWARX":
        """Set the fitted attributes from the fitted steps (and the fitted refinement, whose
        θ_i replace step 5's); returns self.

        Parameters
        ----------
        reg : Regressors
            The training regressors the steps were fitted on.
        local_models, clustering, submodels, regions : fitted step estimators
        refinement : fitted refinement step, optional
        signal_range : array-like of shape (2, m + r), optional
            The training range (:func:`~.arx.training_range` of the training experiments,
            as :meth:`fit` records it), kept as ``signal_range_``: the model's data
            envelope. It is taken from the experiments, not from ``reg``: φ's rows hold
            the lagged outputs and inputs only, so they miss each experiment's first
            max(na, nb) − na outputs and its inputs before max(na, nb) − nb and at its last
            sample, and with nb = 0 every input. None: the model records no range (no
            envelope: :meth:`~.arx.ARXModelBase.outside_envelope` raises and the
            evaluation reports no share outside it).

        Raises
        ------
        ValueError
            If ``signal_range`` is not of shape (2, m + r).
        """
        self.n_inputs_ = reg.n_inputs
        self.n_outputs_ = reg.n_outputs
        self.n_features_in_ = self.n_inputs_
        if signal_range is None:
            vars(self).pop("signal_range_", None)  # (none from an earlier fit stays)
        else:
            rng = np.array(signal_range, dtype=float)
            if rng.shape != (2, reg.n_outputs + reg.n_inputs):
                raise ValueError(
                    f"signal_range has shape {rng.shape}; expected (2, outputs + inputs) = "
                    f"{(2, reg.n_outputs + reg.n_inputs)}")
            self.signal_range_ = rng
        self.local_models_, self.clustering_ = local_models, clustering
        self.submodels_, self.regions_ = submodels, regions
        self.thetas_ = self.base_thetas() if refinement is None else refinement.thetas_
        if refinement is not None:
            self.refinement_ = refinement
        self.n_submodels_ = submodels.n_submodels_
        self.labels_ = submodels.labels_
        self.timings_ = {}
        return self

    def resolved_params(self) -> dict:
        """Every parameter as ``get_params(deep=True)`` names it, with the values the fit
        chose filled in (n_ρ, ε, MinPts; on the structured route each output's structure,
        ``structure_y1`` …); fitted models only."""
        out = {"na": self.na, "nb": self.nb, "affine": self.affine}
        if self.search is not None:
            out["search"] = type(self.search).__name__
            out.update({f"search__{k}": v for k, v in self.search.get_params().items()})
        elif self.structured:
            out.update(form=self.form, outputs=self.outputs)
        if self.structured:
            if self.scheduling is not None:
                out["scheduling"] = type(self.scheduling).__name__
                out.update({f"scheduling__{k}": v
                            for k, v in self.scheduling.get_params().items()})
            out.update({f"structure_y{j + 1}": s
                        for j, s in enumerate(self.structure_.structures)})
        for name in ([] if self.structured and self.scheduling is not None else STEPS):
            # the structured route fits the steps once per output group and keeps none
            step = self.steps()[name] if self.structured else getattr(self, name + "_")
            out[name] = type(step).__name__
            params = step.resolved_params() if hasattr(step, "resolved_params") \
                and not self.structured else step.get_params()
            out.update({f"{name}__{k}": v for k, v in params.items()})
        if self.refinement is not None:
            out["refinement"] = type(self.refinement).__name__
            out.update({f"refinement__{k}": v for k, v in self.refinement.get_params().items()})
        return out

    def prediction_state(self) -> dict:
        """What ``predict`` and ``simulate`` read: the model's attributes but
        :attr:`FIT_RECORD` and :attr:`FIT_PARAMS`. Fitted models with equal states predict
        alike, whatever steps and settings fitted them: e.g. the sets of a sweep over ε and
        MinPts whose clusterings end in the same θ_i and regions (the pipeline scores, draws
        and logs such a model once).

        Returns
        -------
        dict
            Attribute name to value (the model's own objects, not copies); fitted models only.
        """
        check_is_fitted(self)
        return {k: v for k, v in vars(self).items()
                if k not in self.FIT_RECORD and k not in self.FIT_PARAMS}

    def to_state_space(self, u: Signals | None = None, y: Signals | None = None, *,
                       padding: float = PADDING, input_names: list[str] | None = None,
                       output_names: list[str] | None = None):
        """The model as a PWA state-space model x⁺ = A_i x + B_i u + f_i, y = C_i x + g_i on
        polyhedral regions of z = [x; u] (:func:`pwa_pipeline.control.to_state_space`, whose
        parameters these are): every route, the regions made explicit inside the data
        envelope (``signal_range_``, or the range of ``u`` and ``y`` when given, widened by
        ``padding``).

        Returns
        -------
        pwa_pipeline.control.PWAStateSpace

        Raises
        ------
        NotImplementedError
            For a region step of one's own whose regions are not an argmax of affine
            functions (named in the message).
        """
        from ..control.conversion import to_state_space

        return to_state_space(self, u, y, padding=padding, input_names=input_names,
                              output_names=output_names)

    def _predict_phi(self, phi: Float2D) -> Float2D:
        if self.structured:
            return self.structure_.predict_phi(phi)
        region = self.regions_.predict(phi)
        return np.einsum("nd,ndm->nm", phi, self.thetas_[region])


def _base_thetas(submodels: BaseEstimator, regions: BaseEstimator) -> np.ndarray:
    """The θ_i that go with fitted regions: the region step's where it refits them with the
    regions (:class:`~.boundaries.ResidualRegions` has ``thetas_``), else step 5's."""
    return getattr(regions, "thetas_", submodels.thetas_)
