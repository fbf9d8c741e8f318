"""Files written whole or not at all, inside a store: atomic writes, clean-up of what a
killed write left, and paths that cannot leave the store."""

import os
import tempfile
import time
from pathlib import Path

#: Age after which a temporary file is taken for one a killed run left behind.
STALE_SECONDS = 3600.0


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


def check_writable(folder: Path, what: str) -> None:
    """Raise a ValueError naming ``folder`` unless it is, or can be created as, a folder this
    process may write (checked before a run, so that nothing half-done is left)."""
    folder = Path(folder)
    existing = next(p for p in (folder, *folder.parents) if p.exists())
    if not existing.is_dir():
        raise ValueError(f"the {what} {folder} cannot be a folder: {existing} is a file")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise ValueError(f"the {what} {folder} is not writable ({existing} is read-only); "
                         f"nothing stored there was changed")


def inside(root: Path, *parts: str) -> Path:
    """``root / parts``, resolved, refused unless it stays inside ``root``."""
    base = root.resolve()
    path = base.joinpath(*parts).resolve()
    if not path.is_relative_to(base):
        raise ValueError(f"storage path {path} would leave the store {base}")
    return path
