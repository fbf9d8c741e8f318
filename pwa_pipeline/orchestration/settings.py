"""The ``settings`` resource: where the pipeline reads its inputs and keeps its caches."""

import os

import dagster as dg
from upath import UPath

from ..config import Configuration, HParamsFile, load_hparams
from ..datasets import DATASETS, Dataset, load_dataset
from .files import store_root
from .paths import default_datasets_path, default_storage_dir
from .registry import DatasetRegistry


class PipelineSettings(dg.ConfigurableResource):
    """Where the pipeline reads its inputs and caches local models.

    Attributes
    ----------
    kuka_path : str
        The KUKA ``.mat`` file or its folder; empty: ``$PWA_KUKA_DATA`` or
        ``../shared/data/kuka-kr300`` beside the project.
    hparams_path : str
        The hyper-parameter file. `build_definitions`
        sets it to the file its partitions were read from; empty: ``$PWA_HPARAMS`` or
        ``data/hparams.toml``.
    datasets_path : str
        The registry of the user's data sets (``python -m pwa_pipeline add-dataset``); set by
        ``build_definitions`` like ``hparams_path``; empty: ``$PWA_DATASETS`` or
        ``<project>/storage/datasets.json``.
    cache_dir : str
        Cache of fitted PWA models, of local models, of step 5, of the baselines and of
        scores and figures, a folder or an fsspec URL; empty: ``cache`` in the asset store
        (``$PWA_STORAGE`` or ``<project>/storage``).
    cache_models : bool
        Reuse a partition's fitted PWA model (with its structure search) while its data,
        its hyper-parameters and the installed versions of this package and its numerical
        libraries are unchanged: a rerun then fits nothing. Any change fits again.
    cache_local_models : bool
        Reuse local models across hyper-parameter sets that differ only in later steps.
    cache_sub_models : bool
        Reuse step 5's refinement (``RefinedSubModels(memory=...)``) across sets whose
        clusterings consolidate to the same sub-models (e.g. sets that differ only in ε).
    cache_baselines : bool
        Reuse the fitted baselines across the sets of a data set with the same baseline
        settings.
    cache_scores : bool
        Reuse a model's scores and figures (prediction; for a PWA model also its switching
        and regions figures) across sets whose fitted models predict alike
        (`predictor_fingerprint`): a
        baseline shared by the sets of a data set, or a PWA model that sets differing only
        in ε or MinPts end in.
    """

    kuka_path: str = ""
    hparams_path: str = ""
    datasets_path: str = ""
    cache_dir: str = ""
    cache_models: bool = True
    cache_local_models: bool = True
    cache_sub_models: bool = True
    cache_baselines: bool = True
    cache_scores: bool = True

    def with_files(self, hparams_path: str | os.PathLike,
                   datasets_path: str | os.PathLike) -> "PipelineSettings":
        """A copy reading the hyper-parameter file and data-set registry given.

        (pydantic's ``model_copy(update=...)`` changes the attribute but not the
        configuration Dagster runs with, so the copy is built anew.)
        """
        values = {name: getattr(self, name) for name in type(self).model_fields}
        return type(self)(**{**values, "hparams_path": str(hparams_path),
                             "datasets_path": str(datasets_path)})

    def hparams(self) -> HParamsFile:
        """The hyper-parameter file, read and checked (once while it is unchanged,
        `load_hparams`)."""
        return load_hparams(self.hparams_path or None)

    def registry(self) -> DatasetRegistry:
        """The user's registered data sets."""
        return DatasetRegistry(self.datasets_path or default_datasets_path())

    def dataset(self, name: str) -> Dataset:
        """The named data set (raises FileNotFoundError naming the path if its file is
        absent)."""
        if name in DATASETS:
            return load_dataset(name, kuka_path=self.kuka_path or None)
        registry = self.registry()
        if name not in registry.names():
            raise ValueError(f"unknown data set {name!r}; known: "
                             f"{[*DATASETS, *registry.names()]}")
        return registry.get(name).load()

    def configuration(self, hparams: str, dataset: str) -> Configuration:
        """The resolved configuration of one partition; a registered data set brings its
        orders (see `HParamsFile.configuration`)."""
        registry = self.registry()
        orders = registry.get(dataset).orders() if dataset in registry.names() else None
        return self.hparams().configuration(hparams, dataset, orders)

    def cache_root(self) -> UPath:
        """The cache folder (local models, step 5, baselines, scores and figures): a folder or
        an fsspec URL, like the asset store's."""
        return store_root(self.cache_dir) if self.cache_dir else default_storage_dir() / "cache"

    def exports_root(self) -> UPath:
        """Where files made for use outside the tool are written (the state-space models'
        JSON and MPT3 scripts): ``exports`` beside the cache folder, so
        ``<project>/storage/exports`` by default."""
        return self.cache_root().parent / "exports"
