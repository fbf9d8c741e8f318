"""The asset store: each asset partition a file under one folder, local or an fsspec URL.

A pandas DataFrame is written as Parquet (pyarrow) with its signature beside it
(`signed_tables`); any other value (fitted step objects and estimators, the core's
frozen dataclasses) as a signed pickle (`signed_pickles`). A table or pickle whose
signature does not match (cut short, edited, planted) is refused naming it; reading every
partition (the leaderboard), it is left out as not materialised, with a warning naming it.
Files live at ``<base_dir>/<asset>/<dataset>/<hparams>.{parquet,pkl}`` (an unpartitioned
asset: ``<base_dir>/<asset>.{parquet,pkl}``), where ``base_dir`` is a folder or any fsspec
URL (``s3://bucket/pwa``, ``file:///shared/pwa``): workers on other machines read and write
the same files. The names are checked against
`pwa_pipeline._validation.NAME_PATTERN` and every path is checked to stay inside the
store. Every write goes to a temporary file and is moved into place
(`files.atomic_write`), so a failed or killed run never leaves a half-written file
under a name that is read; temporary files a killed run left behind are removed once they
are an hour old.
"""

import dagster as dg
import pandas as pd
from upath import UPath

from .._validation import check_name
from .files import inside, store_root, sweep_stale_tmp
from .partitions import PartitionKey
from .paths import default_storage_dir
from .signed_pickles import UnsignedFileError, load_object, save_object, signing_key
from .signed_tables import load_table, save_table, signature_path

#: Input metadata key: load every materialised partition of the upstream asset as a dict.
ALL_PARTITIONS = "all_partitions"


class PartitionedFileIOManager(dg.ConfigurableIOManager):
    """Stores each asset partition as Parquet (tables) or a signed pickle (everything else).

    ``base_dir`` is a folder or an fsspec URL; empty means ``$PWA_STORAGE`` or
    ``<project>/storage``. See the module doc for the layout.
    """

    base_dir: str = ""

    def root(self) -> UPath:
        """The store's folder (a local path or an fsspec URL)."""
        return store_root(self.base_dir) if self.base_dir else default_storage_dir()

    def _paths(self, asset_key: dg.AssetKey, partition_key: str | None) -> dict[str, UPath]:
        """The two files one asset partition (or an unpartitioned asset) may be stored as, by
        format."""
        asset = [check_name(part, "asset") for part in asset_key.path]
        if partition_key is None:
            return {fmt: inside(self.root(), *asset[:-1], f"{asset[-1]}.{fmt}")
                    for fmt in ("parquet", "pkl")}
        part = PartitionKey.parse(partition_key)
        dataset, hparams = part.dataset, part.hparams
        check_name(dataset, "data set")
        check_name(hparams, "hyper-parameter set")
        return {fmt: inside(self.root(), *asset, dataset, f"{hparams}.{fmt}")
                for fmt in ("parquet", "pkl")}

    def handle_output(self, context: dg.OutputContext, obj) -> None:
        key = context.asset_partition_key if context.has_asset_partitions else None
        paths = self._paths(context.asset_key, key)
        sweep_stale_tmp(paths["pkl"].parent)
        path = paths["parquet" if isinstance(obj, pd.DataFrame) else "pkl"]
        try:
            if isinstance(obj, pd.DataFrame):
                save_table(path, obj, signing_key(self.root()))
            else:
                save_object(path, obj, signing_key(self.root()))
        except OSError as exc:  # a full disk, a store made read-only
            raise dg.Failure(description=(
                f"cannot write {path}: {exc.strerror or exc}; the file it would replace, and "
                f"everything stored before, are kept")) from None
        for other in paths.values():
            if other != path:
                other.unlink(missing_ok=True)
        if path != paths["parquet"]:
            signature_path(paths["parquet"]).unlink(missing_ok=True)
        context.add_output_metadata({"path": dg.MetadataValue.path(str(path))})

    def load(self, asset_key: dg.AssetKey, partition_key: str | None):
        """The stored value of an asset (partition); FileNotFoundError naming what was
        never materialised, `UnsignedFileError` naming a file whose
        signature does not match."""
        paths = self._paths(asset_key, partition_key)
        if paths["parquet"].is_file():
            return load_table(paths["parquet"], signing_key(self.root()))
        if not paths["pkl"].is_file():
            raise FileNotFoundError(
                f"{'/'.join(asset_key.path)}"
                f"{'' if partition_key is None else f' for partition {partition_key}'} has not "
                f"been materialised (no {paths['pkl']})"
            )
        return load_object(paths["pkl"], signing_key(self.root()))

    def load_input(self, context: dg.InputContext):
        """One stored value; for an input declared with ``metadata={ALL_PARTITIONS: True}``
        (an unpartitioned asset reading every partition upstream), ``{partition key: value}``
        of the partitions materialised, the others left out, and those whose file does not
        match its signature too, with a warning naming it (so that one damaged file does
        not fail every later leaderboard)."""
        if not context.has_asset_partitions:
            return self.load(context.asset_key, None)
        if not (context.definition_metadata or {}).get(ALL_PARTITIONS):
            return self.load(context.asset_key, context.asset_partition_key)
        found = {}
        for key in context.asset_partition_keys:
            try:
                found[str(key)] = self.load(context.asset_key, str(key))
            except FileNotFoundError:
                continue
            except UnsignedFileError as exc:
                context.log.warning(f"{exc}; left out")
        return found
