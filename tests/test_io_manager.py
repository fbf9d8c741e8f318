"""The asset store's layout: one file per asset partition, inside the store."""


import dagster as dg
import pandas as pd
import pytest

from pwa_pipeline.orchestration.files import inside
from pwa_pipeline.orchestration.io_manager import PartitionedFileIOManager


def test_paths_cannot_leave_the_store(tmp_path):
    assert inside(tmp_path, "a", "b.pkl") == (tmp_path / "a" / "b.pkl").resolve()
    for bad in (("..", "x.pkl"), ("/etc", "passwd"), ("a", "../../x")):
        with pytest.raises(ValueError, match="would leave the store"):
            inside(tmp_path, *bad)
    io = PartitionedFileIOManager(base_dir=str(tmp_path))
    for key in ("hure_vasak|../../out", "hure_vasak|set?", "../x|paper", "hure_vasak|eps0.1"):
        ctx = dg.build_output_context(asset_key=dg.AssetKey("comparison"), partition_key=key)
        with pytest.raises(ValueError, match="invalid (hyper-parameter set|data set) name"):
            io.handle_output(ctx, pd.DataFrame({"a": [1]}))
    assert [p.name for p in tmp_path.iterdir()] == []


def test_similar_names_never_share_a_file(tmp_path):
    io = PartitionedFileIOManager(base_dir=str(tmp_path))
    for name, value in (("eps0_1", 1), ("eps0_3", 3), ("eps0", 0)):
        ctx = dg.build_output_context(asset_key=dg.AssetKey("x"), partition_key=f"d|{name}")
        io.handle_output(ctx, {"value": value})
    for name, value in (("eps0_1", 1), ("eps0_3", 3), ("eps0", 0)):
        ctx = dg.build_input_context(asset_key=dg.AssetKey("x"), partition_key=f"d|{name}")
        assert io.load_input(ctx) == {"value": value}
    # a table replaces the pickle of the same partition, and only that one
    ctx = dg.build_output_context(asset_key=dg.AssetKey("x"), partition_key="d|eps0")
    io.handle_output(ctx, pd.DataFrame({"a": [1]}))
    assert sorted(p.name for p in (tmp_path / "x" / "d").iterdir()) == [
        "eps0.parquet", "eps0_1.pkl", "eps0_3.pkl"]

