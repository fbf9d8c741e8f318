"""Files: atomic writes, the partitioned IO manager, and the local-model cache.

Format. A pandas DataFrame is written as Parquet (pyarrow); any other value (the core's
frozen dataclasses of numpy arrays, fitted estimators) as a Python pickle (protocol 5).
Files live at ``<base_dir>/<asset>/<dataset>/<hparams>.{parquet,pkl}``. Every write goes to
a temporary file in the same folder and is moved into place with ``os.replace``, so a
failed run never leaves a half-written file and a re-materialisation replaces the old one
at once. Pickles are for this trusted local store only: load none from elsewhere.
"""

import hashlib
import os
import pickle
import tempfile
from pathlib import Path

import dagster as dg
import numpy as np
import pandas as pd

from .partitions import split_key
from .paths import default_storage_dir


def atomic_write(path: Path, write) -> None:
    """Call ``write(tmp_path)`` then move the temporary file onto ``path``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        write(Path(tmp))
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def save_object(path: Path, obj) -> None:
    """Pickle ``obj`` to ``path`` atomically."""
    atomic_write(path, lambda p: p.write_bytes(pickle.dumps(obj, protocol=5)))


def load_object(path: Path):
    """Read a pickle written by :func:`save_object`."""
    return pickle.loads(path.read_bytes())


class PartitionedFileIOManager(dg.ConfigurableIOManager):
    """Stores each asset partition as Parquet (tables) or pickle (everything else).

    ``base_dir`` empty means ``<project>/storage``.
    """

    base_dir: str = ""

    def _root(self) -> Path:
        return Path(self.base_dir).resolve() if self.base_dir else default_storage_dir()

    def _stem(self, context) -> Path:
        dataset, hparams = split_key(context.asset_partition_key)
        return self._root() / "/".join(context.asset_key.path) / dataset / hparams

    def handle_output(self, context: dg.OutputContext, obj) -> None:
        stem = self._stem(context)
        if isinstance(obj, pd.DataFrame):
            path = stem.with_suffix(".parquet")
            atomic_write(path, lambda p: obj.to_parquet(p, index=False))
        else:
            path = stem.with_suffix(".pkl")
            save_object(path, obj)
        for stale in stem.parent.glob(stem.name + ".*"):
            if stale != path and not stale.name.endswith(".tmp"):
                stale.unlink()
        context.add_output_metadata({"path": dg.MetadataValue.path(str(path))})

    def load_input(self, context: dg.InputContext):
        stem = self._stem(context)
        if stem.with_suffix(".parquet").is_file():
            return pd.read_parquet(stem.with_suffix(".parquet"))
        path = stem.with_suffix(".pkl")
        if not path.is_file():
            raise FileNotFoundError(
                f"{'/'.join(context.asset_key.path)} for partition "
                f"{context.asset_partition_key} has not been materialised (no {path})"
            )
        return load_object(path)


def cache_key(phi: np.ndarray, target: np.ndarray, **settings) -> str:
    """Content hash of the regressors and the settings local models depend on."""
    h = hashlib.sha256()
    for arr in (phi, target):
        h.update(np.ascontiguousarray(arr).tobytes())
        h.update(str(arr.shape).encode())
    h.update(repr(sorted(settings.items())).encode())
    return h.hexdigest()[:24]
