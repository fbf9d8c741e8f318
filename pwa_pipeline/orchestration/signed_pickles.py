"""Signed pickles: the trust boundary of the asset store.

A pickle can run code when loaded, so only files carrying a valid signature are unpickled:
ones this store wrote. Each file is a header, an HMAC-SHA256 of the payload under the store's
key, then the pickle (protocol 5), written atomically (`files.atomic_write`). The key
is ``<store>/.signing-key``, created on first use, readable by its owner only in a local
folder (in a bucket, by whoever the bucket's policy lets read it); whoever can write that
key can make the store load code, so keep the store private. A file without a
valid signature (planted, copied from another store, truncated) is refused with its path.
"""

import hashlib
import hmac
import pickle
import secrets

from upath import UPath

from .files import atomic_write, create_new

MAGIC = b"pwa-pipeline signed pickle 1\n"
KEY_FILE = ".signing-key"


class UnsignedFileError(ValueError):
    """A stored pickle or table (`signed_tables`) whose signature is missing or wrong:
    not written by this store, or damaged."""


def signing_key(root: UPath) -> bytes:
    """The store's HMAC key (``<root>/.signing-key``), created on first use (mode 0600)."""
    path = root / KEY_FILE
    if not path.is_file():
        root.mkdir(parents=True, exist_ok=True)
        create_new(path, secrets.token_bytes(32), 0o600)  # or another process's key
    return path.read_bytes()


def save_object(path: UPath, obj, key: bytes) -> None:
    """Pickle ``obj`` to ``path`` atomically, signed with ``key``."""
    payload = pickle.dumps(obj, protocol=5)
    digest = hmac.new(key, payload, hashlib.sha256).digest()
    atomic_write(path, lambda tmp: tmp.write_bytes(MAGIC + digest + payload))


def load_object(path: UPath, key: bytes):
    """Unpickle a file written by `save_object` with the same key.

    Raises
    ------
    UnsignedFileError
        If the header or signature is missing or wrong (the file is then never unpickled).
    """
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
    return pickle.loads(payload)
