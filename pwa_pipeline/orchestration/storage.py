"""Files: atomic writes, signed pickles, the partitioned IO manager, and the caches of the
local models and of step 5.

Format. A pandas DataFrame is written as Parquet (pyarrow); any other value (fitted step
objects and estimators, the core's frozen dataclasses) as a signed pickle: a header, an
HMAC-SHA256 of the payload under the store's key, then the pickle (protocol 5). Files live at
``<base_dir>/<asset>/<dataset>/<hparams>.{parquet,pkl}`` (an unpartitioned asset:
``<base_dir>/<asset>.{parquet,pkl}``); the names are checked against
:data:`pwa_pipeline._validation.NAME_PATTERN` and every path is resolved and checked to stay
inside the store. Every write goes to a temporary file in the same folder and is moved into place
with ``os.replace``, so a failed or killed run never leaves a half-written file; temporary
files a killed run left behind are removed once they are an hour old. A pickle with the same
bytes and key as a file this process wrote or verified, still unchanged, is not written
again but hard-linked to that file (the sets of a sweep store the same regressors and local
models): files are only ever replaced, never written in place, so the names behave as
copies.

Trust boundary. A pickle can run code when loaded, so only files carrying a valid signature
are unpickled: ones this store wrote. The key is ``<store>/.signing-key``, created on first
use, readable by its owner only; whoever can write that key can make the store load code, so
keep the store private. A file without a valid signature (planted, copied from another store,
truncated) is refused with its path; a cache entry is then recomputed.
"""

import functools
import hashlib
import hmac
import inspect
import logging
import os
import pickle
import secrets
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import dagster as dg
import joblib
import numpy as np
import pandas as pd

from .._arrays import array_digest
from .._validation import check_name
from .partitions import split_key
from .paths import default_storage_dir

MAGIC = b"pwa-pipeline signed pickle 1\n"
KEY_FILE = ".signing-key"
#: Age after which a temporary file is taken for one a killed run left behind.
STALE_SECONDS = 3600.0
#: Input metadata key: load every materialised partition of the upstream asset as a dict.
ALL_PARTITIONS = "all_partitions"


class UnsignedFileError(ValueError):
    """A pickle whose signature is missing or wrong: not written by this store, or damaged."""


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


def sweep_stale_tmp(folder: Path, older_than: float = STALE_SECONDS) -> list[Path]:
    """Delete the temporary files of :func:`atomic_write` in ``folder`` older than
    ``older_than`` seconds (a running write is seconds old); returns what was deleted."""
    if not folder.is_dir():
        return []
    cutoff = time.time() - older_than
    stale = [p for p in folder.iterdir() if p.name.startswith(".") and p.name.endswith(".tmp")
             and p.is_file() and p.stat().st_mtime < cutoff]
    for p in stale:
        p.unlink(missing_ok=True)
    return stale


def create_new(path: Path, data: bytes, mode: int) -> bool:
    """Create ``path`` holding ``data``, with permissions ``mode``, unless it exists: written
    to a temporary file beside it, then hard-linked into place, which is atomic and never
    replaces a file another process created meanwhile. True if this call created it."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.chmod(tmp, mode)
        os.link(tmp, path)
        return True
    except FileExistsError:
        return False
    finally:
        os.unlink(tmp)


def signing_key(root: Path) -> bytes:
    """The store's HMAC key (``<root>/.signing-key``), created on first use (mode 0600)."""
    path = root / KEY_FILE
    if not path.is_file():
        root.mkdir(parents=True, exist_ok=True)
        create_new(path, secrets.token_bytes(32), 0o600)  # or another process's key
    return path.read_bytes()


class _VerifiedPayloads:
    """The payloads of the signed files this process wrote or verified last, each with the
    file's identity then (device, inode, size, modification and change times in ns): while
    a file keeps that identity it is unpickled from memory, neither read nor verified again
    (a run's steps load the same regressors and local models several times; 10 MB each on
    the robot). Rewriting, replacing or touching a file changes its identity (its change
    time at least), so it is then read and verified anew. Only payloads this process signed
    or verified are ever kept: the identity tells whether the file still holds one, never
    lets an unverified one in. Each is kept with its signature, by which :meth:`signed_as`
    finds a file to link to in place of writing the same payload again. Payloads over a
    quarter of ``max_bytes`` are not kept; the least recently used beyond ``max_bytes`` (a
    payload kept for several files counted once) are dropped."""

    def __init__(self, max_bytes: int):
        self.max_bytes = max_bytes
        self._kept: dict[tuple[str, bytes], tuple[tuple, bytes, bytes]] = {}
        self._lock = threading.Lock()  # (steps of one process may run in threads)

    @staticmethod
    def identity(path: Path) -> tuple:
        """What tells a file's versions apart: device, inode, size, modification and change
        times."""
        st = path.stat()
        return st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns

    def get(self, path: Path, key: bytes) -> bytes | None:
        """The payload of ``path`` signed with ``key``, if kept and the file is unchanged."""
        with self._lock:
            kept = self._kept.pop((str(path), key), None)
            if kept is None or kept[0] != self.identity(path):
                return None
            self._kept[(str(path), key)] = kept  # most recently used last
            return kept[1]

    def signed_as(self, digest: bytes) -> tuple[Path, tuple, bytes] | None:
        """A kept file, unchanged, whose payload has signature ``digest`` (an HMAC: the same
        payload signed with another store's key has another), with its identity and that
        payload; None if there is none."""
        with self._lock:
            for (name, _), (identity, payload, signed) in reversed(self._kept.items()):
                if hmac.compare_digest(signed, digest):
                    try:
                        if self.identity(Path(name)) == identity:
                            return Path(name), identity, payload
                    except FileNotFoundError:
                        continue
            return None

    def put(self, path: Path, key: bytes, payload: bytes, identity: tuple,
            digest: bytes) -> None:
        """Keep the payload written to or verified at ``path`` when the file had
        ``identity``, with its signature ``digest``, unless the file has changed since
        (another process replaced it)."""
        with self._lock:
            self._kept.pop((str(path), key), None)
            if len(payload) > self.max_bytes // 4 or self.identity(path) != identity:
                return
            self._kept[(str(path), key)] = (identity, payload, digest)
            while sum(len(p) for p in {id(p): p for _, p, _ in self._kept.values()}.values()
                      ) > self.max_bytes:
                del self._kept[next(iter(self._kept))]


_VERIFIED = _VerifiedPayloads(max_bytes=128 * 2**20)


def save_object(path: Path, obj, key: bytes) -> None:
    """Pickle ``obj`` to ``path`` atomically, signed with ``key``; hard-linked to a file
    this process wrote or verified with the same signed payload, unchanged since, instead of
    written again (:func:`_link_same`)."""
    payload = pickle.dumps(obj, protocol=5)
    digest = hmac.new(key, payload, hashlib.sha256).digest()
    same = _VERIFIED.signed_as(digest)
    if same is not None and _link_same(path, key, *same, digest):
        return
    written = []

    def write(tmp: Path) -> None:
        tmp.write_bytes(MAGIC + digest + payload)
        written.append(os.stat(tmp).st_ino)

    atomic_write(path, write)
    identity = _VERIFIED.identity(path)
    if identity[1] == written[0]:  # the file is the one just written, not another's since
        _VERIFIED.put(path, key, payload, identity, digest)


class _SourceChanged(OSError):
    """The file :func:`_link_same` linked to is no longer the one that was verified."""


def _link_same(path: Path, key: bytes, source: Path, identity: tuple, payload: bytes,
               digest: bytes) -> bool:
    """Put a hard link to ``source`` (a kept file that had ``identity`` and holds
    ``payload``, signed ``digest``) in place of ``path`` through :func:`atomic_write`;
    False, and ``path`` unchanged, where the file system refuses the link (another device,
    no hard links, too many of them) or ``source`` was replaced since it was kept. Both
    names are then kept with the file's new identity (the link changed its change time)."""

    def link(tmp: Path) -> None:
        tmp.unlink()  # (atomic_write's empty temporary file: the link takes its name)
        os.link(source, tmp)
        if _VERIFIED.identity(tmp)[:4] != identity[:4]:  # device, inode, size, mtime
            raise _SourceChanged(source)

    try:
        atomic_write(path, link)
    except OSError:
        return False
    linked = _VERIFIED.identity(path)
    for name in (source, path):
        _VERIFIED.put(name, key, payload, linked, digest)
    return True


def load_object(path: Path, key: bytes):
    """Unpickle a file written by :func:`save_object` with the same key (from memory when
    this process wrote or verified it and it is unchanged since, :class:`_VerifiedPayloads`).

    Raises
    ------
    UnsignedFileError
        If the header or signature is missing or wrong (the file is then never unpickled).
    """
    payload = _VERIFIED.get(path, key)
    if payload is None:
        identity = _VERIFIED.identity(path)
        data = path.read_bytes()
        head = len(MAGIC)
        digest, payload = data[head:head + 32], data[head + 32:]
        expected = hmac.new(key, payload, hashlib.sha256).digest()
        if not data.startswith(MAGIC) or not hmac.compare_digest(digest, expected):
            raise UnsignedFileError(
                f"{path} is not a file this store wrote (missing or wrong signature: planted, "
                f"copied from another store, or damaged); it was not loaded. Delete it and "
                f"materialise again"
            )
        _VERIFIED.put(path, key, payload, identity, digest)  # kept if not replaced meanwhile
    return pickle.loads(payload)


def inside(root: Path, *parts: str) -> Path:
    """``root / parts``, resolved, refused unless it stays inside ``root``."""
    base = root.resolve()
    path = base.joinpath(*parts).resolve()
    if not path.is_relative_to(base):
        raise ValueError(f"storage path {path} would leave the store {base}")
    return path


class PartitionedFileIOManager(dg.ConfigurableIOManager):
    """Stores each asset partition as Parquet (tables) or a signed pickle (everything else).

    ``base_dir`` empty means ``<project>/storage``. See the module doc for the layout and the
    trust boundary.
    """

    base_dir: str = ""

    def _root(self) -> Path:
        return Path(self.base_dir).resolve() if self.base_dir else default_storage_dir()

    def _paths(self, asset_key: dg.AssetKey, partition_key: str | None) -> dict[str, Path]:
        """The two files one asset partition (or an unpartitioned asset) may be stored as, by
        format."""
        asset = [check_name(part, "asset") for part in asset_key.path]
        if partition_key is None:
            return {fmt: inside(self._root(), *asset[:-1], f"{asset[-1]}.{fmt}")
                    for fmt in ("parquet", "pkl")}
        dataset, hparams = split_key(partition_key)
        check_name(dataset, "data set")
        check_name(hparams, "hyper-parameter set")
        return {fmt: inside(self._root(), *asset, dataset, f"{hparams}.{fmt}")
                for fmt in ("parquet", "pkl")}

    def handle_output(self, context: dg.OutputContext, obj) -> None:
        key = context.asset_partition_key if context.has_asset_partitions else None
        paths = self._paths(context.asset_key, key)
        sweep_stale_tmp(paths["pkl"].parent)
        if isinstance(obj, pd.DataFrame):
            path = paths["parquet"]
            atomic_write(path, lambda p: obj.to_parquet(p, index=False))
        else:
            path = paths["pkl"]
            save_object(path, obj, signing_key(self._root()))
        for other in paths.values():
            if other != path:
                other.unlink(missing_ok=True)
        context.add_output_metadata({"path": dg.MetadataValue.path(str(path))})

    def load(self, asset_key: dg.AssetKey, partition_key: str | None):
        """The stored value of an asset (partition), or FileNotFoundError naming what was
        never materialised."""
        paths = self._paths(asset_key, partition_key)
        if paths["parquet"].is_file():
            return pd.read_parquet(paths["parquet"])
        if not paths["pkl"].is_file():
            raise FileNotFoundError(
                f"{'/'.join(asset_key.path)}"
                f"{'' if partition_key is None else f' for partition {partition_key}'} has not "
                f"been materialised (no {paths['pkl']})"
            )
        return load_object(paths["pkl"], signing_key(self._root()))

    def load_input(self, context: dg.InputContext):
        """One stored value; for an input declared with ``metadata={ALL_PARTITIONS: True}``
        (an unpartitioned asset reading every partition upstream), ``{partition key: value}``
        of the partitions materialised, the others left out."""
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
        return found


def cache_key(phi: np.ndarray, target: np.ndarray, **settings) -> str:
    """Content hash of the regressors, the numerical core's source (:func:`core_fingerprint`)
    and the settings local models depend on."""
    h = hashlib.sha256(core_fingerprint().encode())
    h.update(array_digest(phi, target).encode())
    h.update(repr(sorted(settings.items())).encode())
    return h.hexdigest()[:24]


def load_or_compute(path: Path, root: Path, compute: Callable[[], object],
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
    """Hash of the numerical core's source (the packages ``pwa``, ``baselines`` and
    ``scoring`` of ``pwa_pipeline``, and the modules they share): part of every cache key, so
    that entries computed by other code are never loaded."""
    package = Path(__file__).resolve().parents[1]
    return source_fingerprint([*package.glob("_*.py"),
                               *(p for sub in ("pwa", "baselines", "scoring")
                                 for p in (package / sub).glob("*.py"))])


class SignedMemory:
    """The ``joblib.Memory`` interface over this store's signed pickles, for
    ``RefinedSubModels(memory=...)``: ``cache(func)`` returns ``func`` whose result is kept at
    ``<root>/<folder>/<key>.pkl``, the key a hash of the function, the numerical core's source
    (:func:`core_fingerprint`), ``salt`` (e.g. the source fingerprint of other code the
    function calls) and the arguments (``joblib.hash``) but those named in ``ignore``, as
    joblib's. An entry without a valid
    signature, or unreadable, is recomputed after ``warn`` (a logging function) names it.
    ``hits`` and ``misses`` count the calls answered from the cache and computed. A handle on
    the store: copies (``clone`` of the step holding it) are this object."""

    def __init__(self, root: Path, folder: str, warn=logging.getLogger(__name__).warning,
                 salt: str = ""):
        self.root, self.folder, self.warn, self.salt = Path(root), folder, warn, salt
        self.hits = self.misses = 0

    def __deepcopy__(self, memo: dict) -> "SignedMemory":
        return self

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
