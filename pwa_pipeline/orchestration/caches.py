"""Caches in the store: fitted PWA models (reused by a rerun), local models, step 5,
baselines, scores and figures (reused across the hyper-parameter sets of a sweep), in a
folder or at an fsspec URL beside the assets (so that workers on other machines share
them).

Each entry is a signed pickle (`signed_pickles`) keyed by a hash of its inputs and of
the numerical core's source (`core_fingerprint`), so an entry computed by other code
is never loaded; an unusable entry is recomputed after a warning.
"""

import functools
import hashlib
import inspect
import logging
import pickle
from collections.abc import Callable, Sequence
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import joblib
import numpy as np
from upath import UPath

from .._arrays import array_digest
from .files import inside
from .signed_pickles import UnsignedFileError, load_object, save_object, signing_key


def cache_key(phi: np.ndarray, target: np.ndarray, **settings) -> str:
    """Content hash of the regressors, the numerical core's source (`core_fingerprint`)
    and the settings local models depend on."""
    h = hashlib.sha256(core_fingerprint().encode())
    h.update(array_digest(phi, target).encode())
    h.update(repr(sorted(settings.items())).encode())
    return h.hexdigest()[:24]


def load_or_compute(path: UPath, root: UPath, compute: Callable[[], object],
                    warn: Callable[[str], object], what: str = "cache entry",
                    use: bool = True) -> tuple[object, bool]:
    """The object signed at ``path`` in the store ``root`` and True; else ``compute()``,
    saved there, and False. An entry without a valid signature, or unreadable, is recomputed
    after ``warn`` names it (``"<what> <path> unusable (...)"``). ``use`` False: computed,
    no file read or written."""
    if use and path.is_file():
        try:
            return load_object(path, signing_key(root)), True
        except (UnsignedFileError, pickle.UnpicklingError, EOFError, AttributeError) as exc:
            warn(f"{what} {path} unusable ({exc}); recomputing it")
    out = compute()
    if use:
        save_object(path, out, signing_key(root))
    return out, False


def source_fingerprint(paths: Sequence[Path]) -> str:
    """Hash of the names and contents of the source files ``paths``."""
    h = hashlib.sha256()
    for path in sorted(paths):
        h.update(path.name.encode())
        h.update(path.read_bytes())
    return h.hexdigest()[:16]


@functools.cache
def core_fingerprint() -> str:
    """Hash of the library's source (every module of ``pwa_pipeline`` outside
    ``orchestration``): part of every cache key, so that entries computed by other code are
    never loaded."""
    package = Path(__file__).resolve().parents[1]
    return source_fingerprint([p for p in package.rglob("*.py")
                               if "orchestration" not in p.relative_to(package).parts])


#: The installed distributions whose versions `versions` reports: this package and the
#: numerical libraries its fits run on.
DISTRIBUTIONS = ("pwa-pipeline", "numpy", "scipy", "scikit-learn")


@functools.cache
def versions() -> str:
    """The installed versions of `DISTRIBUTIONS` (``"pwa-pipeline 0.1.0, numpy 2.4.0, …"``):
    a salt for entries that another release of any of them could compute otherwise."""
    def installed(name: str) -> str:
        try:
            return version(name)
        except PackageNotFoundError:
            return "not installed"

    return ", ".join(f"{name} {installed(name)}" for name in DISTRIBUTIONS)


class SignedMemory:
    """The ``joblib.Memory`` interface over this store's signed pickles, for
    ``RefinedSubModels(memory=...)``: ``cache(func)`` returns ``func`` whose result is kept at
    ``<root>/<folder>/<key>.pkl`` (``root`` a folder or an fsspec URL, see
    `files.store_root`), the key a hash of the function, the numerical core's source
    (`core_fingerprint`), ``salt`` (e.g. the source fingerprint of other code the
    function calls) and the arguments (``joblib.hash``) but those named in ``ignore``, as
    joblib's. An entry without a valid
    signature, or unreadable, is recomputed after ``warn`` (a logging function) names it.
    ``hits`` and ``misses`` count the calls answered from the cache and computed. A handle on
    the store: copies (``clone`` of the step holding it) are this object."""

    def __init__(self, root: UPath, folder: str, warn=logging.getLogger(__name__).warning,
                 salt: str = ""):
        self.root, self.folder, self.warn, self.salt = UPath(root), folder, warn, salt
        self.hits = self.misses = 0

    def __deepcopy__(self, memo: dict) -> "SignedMemory":
        return self

    def __getstate__(self) -> dict:
        """Where it keeps its entries, without the logging function (a run's logger, which
        does not pickle) or the counts: a step holding it is hashed into cache keys."""
        return {"root": self.root, "folder": self.folder, "salt": self.salt}

    def __setstate__(self, state: dict) -> None:
        self.__init__(state["root"], state["folder"], salt=state["salt"])

    def cache(self, func, ignore: Sequence[str] = ()):
        signature = inspect.signature(func)

        def cached(*args, **kwargs):
            bound = signature.bind(*args, **kwargs)
            bound.apply_defaults()
            hashed = {k: v for k, v in bound.arguments.items() if k not in ignore}
            key = joblib.hash((func.__module__, func.__qualname__, core_fingerprint(),
                               self.salt, hashed))
            path = inside(self.root, self.folder, f"{key}.pkl")
            out, hit = load_or_compute(path, self.root, lambda: func(*args, **kwargs),
                                       self.warn)
            self.hits, self.misses = self.hits + hit, self.misses + (not hit)
            return out

        return cached

    def __repr__(self) -> str:
        return f"SignedMemory({str(self.root)!r}, {self.folder!r})"
