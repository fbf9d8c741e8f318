"""Files written whole or not at all, inside a store: atomic writes, clean-up of what a
killed write left, and paths that cannot leave the store.

A store is a universal path (``universal_pathlib``'s ``UPath`` over fsspec): a local folder,
or any fsspec URL (``file://``, ``s3://``, ``gs://``, …), so that workers on other machines
read and write the same files (``memory://`` too, in a test; a run refuses it,
`check_writable`). A local folder is written through the
operating system (a temporary file renamed into place); any other store through fsspec (the
file written locally, uploaded under a temporary name beside its destination, then moved
onto it: a rename on a file system, a whole-object copy on an object store), so that no
reader ever sees half a file.
"""

import os
import secrets
import tempfile
import time
from pathlib import Path

import fsspec
from upath import UPath

from .credentials import mask_credentials

#: Age after which a temporary file is taken for one a killed run left behind.
STALE_SECONDS = 3600.0
#: fsspec protocols whose files live only in the process that wrote them: a run's stores
#: there would be lost when it ends (and other processes never see them).
NON_PERSISTENT_PROTOCOLS = frozenset({"memory"})


def store_root(location: str | os.PathLike) -> UPath:
    """The store at ``location``: a local folder (made absolute) or an fsspec URL.

    Raises
    ------
    ValueError
        Naming the URL (credentials masked) when its protocol is unknown to fsspec or the
        package implementing it (e.g. ``s3fs`` for ``s3://``) is not installed.
    """
    text = os.fspath(location)
    if "://" not in text:
        return UPath(Path(text).resolve())
    protocol = text.split("://", 1)[0]
    try:
        fsspec.get_filesystem_class(protocol)
    except (ValueError, ImportError) as exc:
        raise ValueError(f"storage URL {mask_credentials(text)} cannot be used: {exc}") from None
    return UPath(text)


def is_local(path: os.PathLike) -> bool:
    """Whether ``path`` is a folder or file of this machine's file system, reached without
    fsspec (a plain path, not a ``file://`` URL)."""
    return isinstance(path, Path)


def atomic_write(path: UPath, write) -> None:
    """Call ``write(tmp_path)`` with a local temporary file, then move it onto ``path``
    (through fsspec for a store that is not a local folder, see the module doc)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if is_local(path):
        folder = path.parent
    else:
        scratch = tempfile.TemporaryDirectory(prefix="pwa-upload-")
        folder = Path(scratch.name)
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        write(Path(tmp))
        if is_local(path):
            os.replace(tmp, path)
            return
        staged = path.parent / f".{path.name}.{secrets.token_hex(6)}.tmp"
        try:
            path.fs.put_file(tmp, staged.path)
            path.fs.mv(staged.path, path.path)
        finally:
            if staged.exists():
                staged.unlink()
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
        if not is_local(path):
            scratch.cleanup()


def _modified(path: UPath) -> float | None:
    """When ``path`` was last written (seconds since the epoch); None where the store does
    not say."""
    if is_local(path):
        return path.stat().st_mtime
    try:
        return path.fs.modified(path.path).timestamp()
    except (NotImplementedError, OSError, ValueError):
        return None


def sweep_stale_tmp(folder: UPath, older_than: float = STALE_SECONDS) -> list[UPath]:
    """Delete the temporary files of `atomic_write` in ``folder`` older than
    ``older_than`` seconds (a running write is seconds old); returns what was deleted."""
    if not folder.is_dir():
        return []
    cutoff = time.time() - older_than
    stale = [p for p in folder.iterdir() if p.name.startswith(".") and p.name.endswith(".tmp")
             and p.is_file() and (mtime := _modified(p)) is not None and mtime < cutoff]
    for p in stale:
        p.unlink(missing_ok=True)
    return stale


def create_new(path: UPath, data: bytes, mode: int) -> bool:
    """Create ``path`` holding ``data``, with permissions ``mode``, unless it exists. True if
    this call created it.

    On a local folder: written to a temporary file beside it, then hard-linked into place,
    which is atomic and never replaces a file another process created meanwhile. Elsewhere
    (fsspec has no create-if-absent) it is written unless found, and the permissions are the
    store's: create such files once, before processes share the store.
    """
    if not is_local(path):
        if path.exists():
            return False
        atomic_write(path, lambda tmp: tmp.write_bytes(data))
        return True
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


def check_writable(folder: UPath, what: str) -> None:
    """Raise a ValueError naming ``folder`` unless it is, or can be created as, a folder this
    process may write and that outlives it (checked before a run, so that nothing half-done
    is left and nothing is computed to be lost). A store that is not a local folder is
    probed by writing and deleting a small file in it; one of
    `NON_PERSISTENT_PROTOCOLS` is refused."""
    if not is_local(folder) and folder.protocol in NON_PERSISTENT_PROTOCOLS:
        raise ValueError(f"the {what} {mask_credentials(str(folder))} is kept only in this "
                         f"process's memory (fsspec's {folder.protocol}://): every asset and "
                         f"export would be lost when the process ends; use a folder or a "
                         f"persistent URL such as s3://bucket/pwa")
    if not is_local(folder):
        probe = folder / f".write-probe-{secrets.token_hex(6)}.tmp"
        try:
            folder.mkdir(parents=True, exist_ok=True)
            probe.write_bytes(b"")
            probe.unlink()
        except Exception as exc:  # each fsspec implementation raises its own errors
            raise ValueError(f"the {what} {mask_credentials(str(folder))} is not writable "
                             f"({type(exc).__name__}: {exc}); nothing stored there was "
                             f"changed") from None
        return
    folder = Path(folder)
    existing = next(p for p in (folder, *folder.parents) if p.exists())
    if not existing.is_dir():
        raise ValueError(f"the {what} {folder} cannot be a folder: {existing} is a file")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise ValueError(f"the {what} {folder} is not writable ({existing} is read-only); "
                         f"nothing stored there was changed")


def inside(root: UPath, *parts: str) -> UPath:
    """``root / parts``, refused unless it stays inside ``root`` (a local path is resolved
    first; elsewhere no part may be empty, ``.``, ``..`` or hold a ``/``)."""
    if is_local(root):
        base = root.resolve()
        path = base.joinpath(*parts).resolve()
        if not path.is_relative_to(base):
            raise ValueError(f"storage path {path} would leave the store {base}")
        return path
    for part in parts:
        if part in ("", ".", "..") or "/" in part or "\\" in part:
            raise ValueError(f"storage path {root}/{'/'.join(parts)} would leave the store "
                             f"{root}")
    return root.joinpath(*parts)
