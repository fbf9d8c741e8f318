"""The trust boundary: only pickles this store signed are loaded."""

import pickle

import dagster as dg
import pytest

from pwa_pipeline.orchestration.io_manager import PartitionedFileIOManager
from pwa_pipeline.orchestration.signed_pickles import (
    UnsignedFileError,
    load_object,
    save_object,
    signing_key,
)

from .._planted import Planted


def test_signed_files_round_trip_and_damage_is_detected(tmp_path):
    key = signing_key(tmp_path)
    assert signing_key(tmp_path) == key and len(key) == 32
    assert (tmp_path / ".signing-key").stat().st_mode & 0o777 == 0o600
    save_object(tmp_path / "a.pkl", {"theta": [1.0, 2.0]}, key)
    assert load_object(tmp_path / "a.pkl", key) == {"theta": [1.0, 2.0]}
    data = (tmp_path / "a.pkl").read_bytes()
    (tmp_path / "a.pkl").write_bytes(data[:-5])  # truncated
    with pytest.raises(UnsignedFileError, match="a.pkl is not a file this store wrote"):
        load_object(tmp_path / "a.pkl", key)


def test_a_planted_pickle_is_never_loaded(tmp_path):
    marker = tmp_path / "marker"
    planted = tmp_path / "store" / "x" / "d" / "s.pkl"
    planted.parent.mkdir(parents=True)
    planted.write_bytes(pickle.dumps(Planted(marker)))
    io = PartitionedFileIOManager(base_dir=str(tmp_path / "store"))
    ctx = dg.build_input_context(asset_key=dg.AssetKey("x"), partition_key="d|s")
    with pytest.raises(UnsignedFileError, match=f"{planted} is not a file this store wrote"):
        io.load_input(ctx)
    assert not marker.exists()
    # signed with another store's key: refused too
    save_object(planted, {"a": 1}, signing_key(tmp_path / "other"))
    with pytest.raises(UnsignedFileError):
        io.load_input(ctx)

