"""The asset store's layout: one file per asset partition, inside the store; a failed write
keeps what was stored."""

import dagster as dg
import pandas as pd
import pytest

from pwa_pipeline.definitions import defs
from pwa_pipeline.orchestration.files import inside
from pwa_pipeline.orchestration.io_manager import PartitionedFileIOManager
from pwa_pipeline.orchestration.settings import PipelineSettings

from .._results import holding


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
        "eps0.parquet", "eps0.parquet.sig", "eps0_1.pkl", "eps0_3.pkl"]
    ctx = dg.build_output_context(asset_key=dg.AssetKey("x"), partition_key="d|eps0")
    io.handle_output(ctx, {"value": 0})  # and a pickle the table, with its signature
    assert sorted(p.name for p in (tmp_path / "x" / "d").iterdir()) == [
        "eps0.pkl", "eps0_1.pkl", "eps0_3.pkl"]



def test_a_full_disk_fails_the_step_naming_the_file_and_keeps_what_was_stored(tmp_path,
                                                                              monkeypatch):
    import errno

    from pwa_pipeline.orchestration import io_manager as module

    store = PartitionedFileIOManager(base_dir=str(tmp_path))
    names = ("configuration", "raw_benchmark", "regressors")
    resources = {"io_manager": store,
                 "settings": PipelineSettings(cache_dir=str(tmp_path / "cache"))}
    first = dg.materialize(holding(defs.assets, names), selection=names,
                           partition_key="hure_vasak|paper", resources=resources)
    before = (tmp_path / "regressors" / "hure_vasak" / "paper.pkl").read_bytes()

    def full(*_):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(module, "save_object", full)
    again = dg.materialize(holding(defs.assets, names), selection=names,
                           partition_key="hure_vasak|paper", resources=resources,
                           raise_on_error=False)
    assert first.success and not again.success
    errors = " ".join(str(e.event_specific_data.error) for e in again.all_events
                      if e.event_type_value == "STEP_FAILURE")
    path = tmp_path / "configuration" / "hure_vasak" / "paper.pkl"
    assert f"cannot write {path}: No space left on device; the file it would replace, and " \
           f"everything stored before, are kept" in errors
    assert (tmp_path / "regressors" / "hure_vasak" / "paper.pkl").read_bytes() == before
