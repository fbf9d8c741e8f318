"""Atomic writes, temporary files a killed write left, paths inside the store."""

import os
import time

import pytest

from pwa_pipeline.orchestration import files
from pwa_pipeline.orchestration.files import atomic_write, store_root, sweep_stale_tmp


def test_create_new_never_replaces_a_file_and_leaves_no_temporary_one(tmp_path):
    path = tmp_path / "f.db"
    assert files.create_new(path, b"first", 0o640)
    assert path.read_bytes() == b"first" and path.stat().st_mode & 0o777 == 0o640
    assert not files.create_new(path, b"second", 0o600)  # another process's file: kept
    assert path.read_bytes() == b"first" and path.stat().st_mode & 0o777 == 0o640
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.db"]


def test_stale_temporary_files_are_swept_fresh_ones_kept(tmp_path):
    old, new = tmp_path / ".a.pkl.x1.tmp", tmp_path / ".a.pkl.x2.tmp"
    for p in (old, new):
        p.write_text("half")
    os.utime(old, (time.time() - 7200, time.time() - 7200))
    (tmp_path / "b.pkl").write_text("kept")
    assert sweep_stale_tmp(tmp_path) == [old]
    assert sorted(p.name for p in tmp_path.iterdir()) == [".a.pkl.x2.tmp", "b.pkl"]



@pytest.mark.parametrize("store", ["folder", "fsspec"])
def test_atomic_write_keeps_the_old_file_when_a_write_fails(store, tmp_path):
    """On a file system (a rename) and an fsspec store (the object written whole)."""
    root = tmp_path if store == "folder" else store_root(f"memory://pwa-atomic/{tmp_path.name}")
    path = root / "x" / "a.parquet"
    atomic_write(path, lambda p: p.write_text("old"))

    def broken(p):
        p.write_text("half")
        raise RuntimeError("connection lost")

    with pytest.raises(RuntimeError, match="connection lost"):
        atomic_write(path, broken)
    assert path.read_text() == "old"
    assert [f.name for f in path.parent.iterdir()] == ["a.parquet"]
