"""Named hyper-parameter sets (``data/hparams.toml``), read and validated once.

The file has one table per set and data set, ``[<set>.<dataset>]``, whose keys configure
[`PWARX`][pwa_pipeline.PWARX]: ``preset`` (``"default"``, ``"paper"`` or
``"auto"``, the classmethod that builds its step objects; ``"auto"`` is the structure search
of `pwa_pipeline.pwa.search.search`, ``na`` and ``nb`` its largest orders, a
sub-table ``search`` its parameters, e.g. ``search.max_candidates = 500``), ``na``, ``nb``,
``affine``, and each step's parameters as a sub-table, e.g. ``clustering.eps = 0.1`` (``clustering__eps`` in
``get_params``). ``[baselines.<dataset>]`` holds the evaluation protocol's ``warmup`` and the
subspace baseline's parameters (``subspace.order``, ``subspace.horizon``). A sub-table
``refinement`` (e.g. ``refinement.max_iter = 30``) adds simulation-error refinement
(`OutputErrorRefinement`) to the PWA model and, so that
the comparison is fair, to the linear ARX baseline. The structures of
`pwa_pipeline.pwa.structures` are keys too: ``form = "velocity"``,
``outputs = "decoupled"`` (shared with the linear ARX baseline) and a sub-table
``scheduling`` (e.g. ``scheduling.switch = "select"``) for user regions
(`SignScheduling`, PWA model only).

A table ``[<set>."*"]`` applies the set to every data set a user registers
(`pwa_pipeline.datasets.user`); it gives no orders, which come from the registration
(``na``, ``nb``, ``affine``). ``[baselines."*"]`` does the same for the baselines. A
data set's own table, ``[<set>.<name>]``, takes precedence. Every estimator is built and its
parameters checked when the file is read, so a bad value fails before any run, with the file,
set and data set in the message.
"""

import functools
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from sklearn.base import BaseEstimator

from ._validation import check_name
from .baselines.subspace import SubspaceSS
from .datasets.user import MAX_ORDER
from .methods import METHODS
from .pwa.estimator import PWARX
from .pwa.output_error import OutputErrorRefinement
from .pwa.scheduling import SignScheduling
from .pwa.search.search import StructureSearch
from .scoring.evaluation import WARMUP

BUNDLED_HPARAMS = Path(__file__).resolve().parents[1] / "data" / "hparams.toml"
BASELINES = "baselines"
#: The table key of a set's values for every user data set.
ANY_DATASET = "*"
ORDERS = ("na", "nb", "affine")
#: The keys of a ``[baselines.<dataset>]`` table: the evaluation's warm-up and the subspace
#: baseline's parameters (a sub-table).
BASELINE_KEYS = {"warmup", "subspace"}
#: Sub-tables that add an optional step object, and an example key of each.
_STEP_TABLES = {"refinement": OutputErrorRefinement, "scheduling": SignScheduling,
                "search": StructureSearch}
_EXAMPLES = {"refinement": "max_iter = 30", "scheduling": 'switch = "select"',
             "search": "max_candidates = 500"}
_PAPER_VALUES = {("local_models", "n_rho"): "n_rho", ("clustering", "eps"): "eps",
                 ("clustering", "min_pts"): "min_pts"}
#: The largest value the file accepts for each count (keys as the file writes them), and
#: what it counts: beyond these a run fails or runs for hours part-way, so the file is refused
#: when it is read. (The library itself takes any value its data allow.)
LIMITS = {
    "na": (MAX_ORDER, "lags per channel; φ has m·na + r·nb entries and each local set needs "
                      "three times as many samples"),
    "nb": (MAX_ORDER, "lags per channel; φ has m·na + r·nb entries and each local set needs "
                      "three times as many samples"),
    "local_models.n_rho": (10_000, "samples in each local set; the paper uses 18 to 61"),
    "clustering.min_pts": (10_000, "local models in a DBSCAN neighbourhood; the paper uses "
                                   "20 to 22"),
    "subspace.order": (100, "states of the subspace model"),
    "subspace.horizon": (100, "block rows of its Hankel matrices, whose size grows as its "
                              "square"),
    "warmup": (10_000, "samples of each held-out experiment that start its simulation"),
}


@dataclass(frozen=True)
class Configuration:
    """Everything one partition (data set × set) needs, resolved once.

    Attributes
    ----------
    hparams, dataset : str
        The set and data set names.
    estimators : dict
        The unfitted estimator of each method of `pwa_pipeline.methods.METHODS`.
    warmup : int
        Warm-up samples of the evaluation protocol.
    source : Path
        The file it was read from.
    """

    hparams: str
    dataset: str
    estimators: dict[str, BaseEstimator]
    warmup: int
    source: Path = field(compare=False)

    @property
    def pwa(self) -> PWARX:
        """The unfitted PWARX estimator."""
        return self.estimators["pwa"]

    def params(self, method: str) -> dict:
        """``method``'s parameters as ``get_params(deep=True)`` names them (step objects
        listed by class name), with the set, data set and warm-up."""
        params = self.estimators[method].get_params(deep=True)
        return {"hparams": self.hparams, "dataset": self.dataset, "warmup": self.warmup,
                **{k: type(v).__name__ if isinstance(v, BaseEstimator) else v
                   for k, v in params.items()}}


def default_hparams_path() -> Path:
    """``$PWA_HPARAMS`` if set, else the bundled ``data/hparams.toml``."""
    env = os.environ.get("PWA_HPARAMS")
    return Path(env).resolve() if env else BUNDLED_HPARAMS


def _flatten(table: dict, prefix: str = "") -> dict:
    out = {}
    for key, value in table.items():
        if isinstance(value, dict):
            out.update(_flatten(value, f"{prefix}{key}__"))
        else:
            out[prefix + key] = value
    return out


def _check_values(table: dict, owner, prefix: str = "") -> None:
    """Refuse what the estimators' own checks let through: a boolean for a parameter that
    takes none (Python counts TOML's ``true`` as the integer 1), and a count above its
    `LIMITS`.

    Parameters
    ----------
    table : dict
        Parameters of ``owner`` as the file gives them, with sub-tables for its step objects.
    owner : estimator or estimator class
        Whose ``_parameter_constraints`` say which parameters take booleans.
    prefix : str
        Prepended to the keys in messages and in `LIMITS` (e.g. ``"subspace."``).

    Raises
    ------
    ValueError
        Naming the key, its value and the rule.
    """
    for key, value in table.items():
        name = prefix + key
        if isinstance(value, dict):
            step = getattr(owner, key, None)
            if isinstance(step, BaseEstimator):
                _check_values(value, step, f"{name}.")
            continue
        constraints = owner._parameter_constraints.get(key)
        if isinstance(value, bool) and constraints is not None and "boolean" not in constraints:
            raise ValueError(f"{name} = {str(value).lower()} is a boolean, which {key} does "
                             f"not take (Python would read it as {int(value)})")
        limit, meaning = LIMITS.get(name, (None, ""))
        if limit is not None and isinstance(value, int | float) and value > limit:
            raise ValueError(f"{name} = {value} is above {limit}, the largest this file "
                             f"accepts ({meaning})")


def build_pwarx(table: dict) -> PWARX:
    """The PWARX estimator a ``[<set>.<dataset>]`` table describes (see the module doc)."""
    table = {k: (dict(v) if isinstance(v, dict) else v) for k, v in table.items()}
    preset = table.pop("preset", "default")
    orders = {k: table.pop(k) for k in ("na", "nb", "affine") if k in table}
    if preset == "default":
        model = PWARX.default(**orders)
    elif preset == "paper":
        values = {}
        for (step, key), arg in _PAPER_VALUES.items():
            if key not in table.get(step, {}):
                missing = [f"{s}.{k}" for s, k in _PAPER_VALUES if k not in table.get(s, {})]
                raise ValueError(
                    f"preset 'paper' needs {', '.join(missing)}: the paper gives them per "
                    f"data set and no rule"
                )
            values[arg] = table[step].pop(key)
        model = PWARX.paper(**orders, **values)
    elif preset == "auto":
        if not orders.pop("affine", True):
            raise ValueError("preset 'auto' fits a constant term (its thresholds need it): "
                             "leave affine out or set it to true")
        model = PWARX.auto(**orders)
    else:
        raise ValueError(f"unknown preset {preset!r}; use 'default', 'paper' or 'auto'")
    for key, step_class in _STEP_TABLES.items():
        if key not in table:
            continue
        values = table.pop(key)
        if not isinstance(values, dict):
            raise ValueError(f"{key} must be a table, e.g. {key}.{_EXAMPLES[key]} (an empty "
                             f"[<set>.<dataset>.{key}] table for the defaults)")
        known = step_class().get_params()
        unknown = sorted(set(values) - set(known))
        if unknown:
            raise ValueError(f"unknown {key} parameter(s) {unknown}; it has {sorted(known)}")
        model.set_params(**{key: step_class(**values)})
    model.set_params(**_flatten(table))
    model._validate_params()
    for step in [*model.step_objects().values(),
                 *filter(None, [model.refinement, model.scheduling, model.search])]:
        step._validate_params()
    return model


def _check_min_pts(clustering) -> None:
    """MinPts no larger than the number of local models DBSCAN is given."""
    min_pts = getattr(clustering, "min_pts", None)
    max_clustered = getattr(clustering, "max_clustered", None)
    if min_pts is not None and max_clustered is not None and min_pts > max_clustered:
        raise ValueError(f"clustering.min_pts = {min_pts} is above clustering.max_clustered = "
                         f"{max_clustered}: DBSCAN clusters at most max_clustered local "
                         f"models, so no neighbourhood could hold min_pts of them")


class HParamsFile:
    """A hyper-parameter file, read, built and validated once.

    Parameters
    ----------
    path : path-like, optional
        Default: `default_hparams_path`.

    Attributes
    ----------
    path : Path
    sets : list of str
        The set names (every top-level table but ``baselines``), in file order.

    Raises
    ------
    FileNotFoundError
        Naming the path.
    ValueError
        Invalid TOML (with the line), a bad name, an unknown parameter or preset, a value
        outside its range, a boolean for a number or a count above `LIMITS`; the
        message names the file, set and data set (or ``[baselines.<dataset>]``).
    """

    def __init__(self, path: str | os.PathLike | None = None):
        self.path = Path(path).resolve() if path is not None else default_hparams_path()
        if not self.path.is_file():
            raise FileNotFoundError(f"hyper-parameter file not found: {self.path}")
        try:
            with self.path.open("rb") as fh:
                tables = tomllib.load(fh)
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise ValueError(f"{self.path} is not valid TOML: {exc}") from None
        self._baselines = tables.pop(BASELINES, {})
        if not tables:
            raise ValueError(f"{self.path} has no hyper-parameter set: add a table "
                             f"[<set>.<dataset>], e.g. [default.hure_vasak]")
        for name, per_dataset in tables.items():
            loose = None if isinstance(per_dataset, dict) else name
            loose = loose or next((f"{name}.{d}" for d, t in per_dataset.items()
                                   if not isinstance(t, dict)), None)
            if loose is not None:
                raise ValueError(f"{self.path}: {loose} must be a table [<set>.<dataset>] of "
                                 f"parameters (e.g. [{name}.hure_vasak] with na = 1), not a "
                                 f"value")
        for dataset, table in self._baselines.items():
            unknown = sorted(set(table) - BASELINE_KEYS) if isinstance(table, dict) else None
            if unknown is None or unknown:
                raise ValueError(
                    f"{self.path}, [{BASELINES}.{dataset}]: "
                    + ("must be a table" if unknown is None else f"unknown key(s) {unknown}")
                    + f"; its keys are {sorted(BASELINE_KEYS)} (e.g. subspace.order = 4)")
            try:
                _check_values({k: v for k, v in table.items() if k != "subspace"}, SubspaceSS)
                if isinstance(table.get("subspace"), dict):
                    _check_values(table["subspace"], SubspaceSS, "subspace.")
            except ValueError as exc:
                raise ValueError(f"{self.path}, [{BASELINES}.{dataset}]: {exc}") from None
        try:
            self.sets = [check_name(name, "hyper-parameter set") for name in tables]
            for per_dataset in tables.values():
                for dataset in set(per_dataset) - {ANY_DATASET}:
                    check_name(dataset, "data set")
        except ValueError as exc:
            raise ValueError(f"{self.path}: {exc}") from None
        self._templates: dict[str, dict] = {}
        self._configs: dict[tuple[str, str], Configuration] = {}
        for name, per_dataset in tables.items():
            for dataset, table in per_dataset.items():
                if dataset == ANY_DATASET:
                    given = [k for k in ORDERS if k in table]
                    if given:
                        raise ValueError(
                            f'{self.path}, [{name}."*"]: {given} come from each data set\'s '
                            f"registration, not from the set")
                    self._templates[name] = table
                    self._build(name, ANY_DATASET, {**table, "na": 1, "nb": 1})  # check it
                    continue
                self._configs[name, dataset] = self._build(name, dataset, table)

    def _build(self, name: str, dataset: str, table: dict) -> Configuration:
        base = {"warmup": WARMUP, **self._baselines.get(
            dataset, self._baselines.get(ANY_DATASET, {}))}
        try:
            pwa = build_pwarx(table)
            _check_values(table, pwa)
            _check_min_pts(pwa.clustering)
            estimators = {m.name: m.build(pwa, base) for m in METHODS.values()}
            for est in estimators.values():
                est._validate_params()
        except (ValueError, TypeError) as exc:
            raise ValueError(f"{self.path}, [{name}.{dataset}]: {exc}") from None
        return Configuration(hparams=name, dataset=dataset, estimators=estimators,
                             warmup=int(base["warmup"]), source=self.path)

    @property
    def datasets(self) -> set[str]:
        """The data sets the file has tables for (in any set, or among the baselines)."""
        return {dataset for _, dataset in self._configs} | (set(self._baselines)
                                                             - {ANY_DATASET})

    def covers(self, hparams: str, dataset: str, registered: bool = False) -> bool:
        """Whether set ``hparams`` has values for ``dataset`` (a user's ``registered`` one
        also through ``[<hparams>."*"]``)."""
        return (hparams, dataset) in self._configs or (registered
                                                       and hparams in self._templates)

    def configuration(self, hparams: str, dataset: str,
                      orders: dict | None = None) -> Configuration:
        """The configuration of set ``hparams`` for ``dataset``.

        Parameters
        ----------
        hparams, dataset : str
        orders : dict, optional
            ``na``, ``nb``, ``affine`` of a user's registered data set: with them, a set
            without a table for ``dataset`` falls back to its ``"*"`` table (a set of
            preset ``"auto"`` takes the orders as its largest and always fits the constant).

        Raises
        ------
        KeyError
            Naming the unknown set or data set and the known ones.
        """
        if hparams not in self.sets:
            raise KeyError(f"unknown hyper-parameter set {hparams!r} in {self.path}; "
                           f"known: {self.sets}")
        if (hparams, dataset) not in self._configs:
            if orders is not None and hparams in self._templates:
                template = self._templates[hparams]
                if template.get("preset") == "auto":  # it always fits the constant
                    orders = {k: v for k, v in orders.items() if k != "affine"}
                return self._build(hparams, dataset, {**template, **orders})
            known = sorted(d for s, d in self._configs if s == hparams)
            raise KeyError(f"hyper-parameter set {hparams!r} has no values for data set "
                           f"{dataset!r} in {self.path}; it has {known}"
                           + ("" if orders is None else
                              f' and no [{hparams}."*"] table for registered data sets'))
        return self._configs[hparams, dataset]


def load_hparams(path: str | os.PathLike | None = None) -> HParamsFile:
    """The hyper-parameter file (default `default_hparams_path`), read and checked once
    per process and read again when it changes (its modification time or size): the
    definitions, the command line and every partition's ``configuration`` share one
    reading.

    Raises
    ------
    FileNotFoundError, ValueError
        As [`HParamsFile`][pwa_pipeline.config.HParamsFile].
    """
    resolved = Path(path).resolve() if path is not None else default_hparams_path()
    if not resolved.is_file():
        return HParamsFile(resolved)  # (raises, naming the path)
    stat = resolved.stat()
    return _read(resolved, (stat.st_mtime_ns, stat.st_size))


@functools.lru_cache(maxsize=16)
def _read(path: Path, stamp: tuple[int, int]) -> HParamsFile:
    """[`HParamsFile`][pwa_pipeline.config.HParamsFile] of ``path`` as it was at ``stamp`` (its modification
    time and size, the cache's key)."""
    return HParamsFile(path)
