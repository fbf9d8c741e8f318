"""Named hyper-parameter sets (``data/hparams.toml``) and the models they configure."""

import os
import tomllib
from dataclasses import dataclass
from pathlib import Path

from .identification import PWARX
from .linear import LinearARX
from .subspace import SubspaceSS

BUNDLED_HPARAMS = Path(__file__).resolve().parents[1] / "data" / "hparams.toml"
BASELINES = "baselines"


@dataclass(frozen=True)
class HParams:
    """One named set for one data set.

    Attributes
    ----------
    name : str
    dataset : str
    pwarx : dict
        Keyword arguments of :class:`~pwa_pipeline.identification.PWARX`.
    baselines : dict
        ``subspace_order``, ``subspace_horizon``, ``warmup``.
    """

    name: str
    dataset: str
    pwarx: dict
    baselines: dict

    @property
    def warmup(self) -> int:
        """Warm-up samples of the evaluation protocol."""
        return int(self.baselines.get("warmup", 10))

    def as_params(self) -> dict:
        """Flat dict of every value, for tracking."""
        out = {"hparams": self.name, "dataset": self.dataset, **self.pwarx}
        out.update({f"baseline_{k}": v for k, v in self.baselines.items()})
        return out

    def pwa_model(self) -> PWARX:
        """The unfitted PWARX estimator."""
        return PWARX(**self.pwarx)

    def linear_model(self) -> LinearARX:
        """Linear ARX with the PWA model's regressors."""
        return LinearARX(self.pwarx.get("na", 1), self.pwarx.get("nb", 1),
                         self.pwarx.get("affine", False))

    def subspace_model(self) -> SubspaceSS:
        """The subspace state-space baseline."""
        return SubspaceSS(order=self.baselines.get("subspace_order"),
                          horizon=int(self.baselines.get("subspace_horizon", 10)),
                          warmup=self.warmup)


def default_hparams_path() -> Path:
    """``$PWA_HPARAMS`` if set (the pipeline's partitions follow it), else ``data/hparams.toml``."""
    env = os.environ.get("PWA_HPARAMS")
    return Path(env) if env else BUNDLED_HPARAMS


def read_hparams(path: str | Path | None = None) -> dict[str, dict[str, dict]]:
    """The raw tables of the hyper-parameter file: ``{set: {dataset: {key: value}}}``."""
    p = Path(path) if path is not None else default_hparams_path()
    if not p.is_file():
        raise FileNotFoundError(f"hyper-parameter file not found: {p}")
    with p.open("rb") as fh:
        return tomllib.load(fh)


def set_names(path: str | Path | None = None) -> list[str]:
    """Names of the hyper-parameter sets (every table but ``baselines``)."""
    return [k for k in read_hparams(path) if k != BASELINES]


def get_hparams(name: str, dataset: str, path: str | Path | None = None) -> HParams:
    """The set ``name`` for ``dataset``.

    Raises
    ------
    KeyError
        Naming the unknown set or data set and the known ones.
    """
    tables = read_hparams(path)
    if name not in tables or name == BASELINES:
        raise KeyError(f"unknown hyper-parameter set {name!r}; known: {set_names(path)}")
    if dataset not in tables[name]:
        raise KeyError(
            f"hyper-parameter set {name!r} has no values for data set {dataset!r}; "
            f"it has {sorted(tables[name])}"
        )
    return HParams(name=name, dataset=dataset, pwarx=dict(tables[name][dataset]),
                   baselines=dict(tables.get(BASELINES, {}).get(dataset, {})))
