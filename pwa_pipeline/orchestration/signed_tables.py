"""Signed tables: Parquet files with their signature beside them.

A table stays a plain Parquet file, readable by any tool, and its HMAC-SHA256 under the
store's key (`signed_pickles.signing_key`) is written to ``<file>.sig`` once the
table is in place, each file atomically (`files.atomic_write`). A table is read only
when the signature matches its bytes: one cut short, edited (by hand, by another program or
another store) or left without its signature by a write killed between the two files is
refused with its path, never read as it says nor failing with pyarrow's ``magic bytes not
found``.
"""

import hashlib
import hmac
import io

import pandas as pd
from upath import UPath

from .files import atomic_write
from .signed_pickles import UnsignedFileError

#: Suffix of the signature file beside a table.
SIGNATURE_SUFFIX = ".sig"


def signature_path(path: UPath) -> UPath:
    """Where the signature of the table at ``path`` is kept."""
    return path.with_name(path.name + SIGNATURE_SUFFIX)


def save_table(path: UPath, table: pd.DataFrame, key: bytes) -> None:
    """Write ``table`` to ``path`` as Parquet (without its index), then its signature under
    ``key`` beside it; each file atomically."""
    buffer = io.BytesIO()
    table.to_parquet(buffer, index=False)
    data = buffer.getvalue()
    atomic_write(path, lambda tmp: tmp.write_bytes(data))
    digest = hmac.new(key, data, hashlib.sha256).hexdigest()
    atomic_write(signature_path(path), lambda tmp: tmp.write_text(digest + "\n"))


def load_table(path: UPath, key: bytes) -> pd.DataFrame:
    """Read a table written by `save_table` with the same key.

    Raises
    ------
    UnsignedFileError
        If its signature is missing or does not match its bytes (the table is then not
        read), naming the file.
    """
    data = path.read_bytes()
    sig = signature_path(path)
    expected = hmac.new(key, data, hashlib.sha256).hexdigest()
    if not (sig.is_file() and hmac.compare_digest(sig.read_text().strip(), expected)):
        raise UnsignedFileError(
            f"{path} does not match its signature {sig.name} (cut short, edited, written by "
            f"another store or before tables were signed); it was not read. Materialise the "
            f"asset (its partition) again to rewrite it")
    return pd.read_parquet(io.BytesIO(data))
