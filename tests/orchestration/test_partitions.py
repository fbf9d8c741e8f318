"""Every partition offered runs: each key's configuration builds, and no other pair is offered."""

import pandas as pd
import pytest

from pwa_pipeline.datasets import DATASETS, make_hure_vasak
from pwa_pipeline.orchestration.definitions import build_definitions, partitions_of
from pwa_pipeline.orchestration.partitions import PartitionKey, all_keys, check_keys

HPARAMS = """
[paper.hure_vasak]
preset = "paper"
na = 1
nb = 1
local_models.n_rho = 18
clustering.eps = 0.1
clustering.min_pts = 20

[robot_only.kuka_robot]
preset = "default"
na = 2
nb = 2

[everywhere.hure_vasak]
preset = "default"
na = 1
nb = 1

[everywhere.kuka_robot]
preset = "default"
na = 2
nb = 2

[everywhere."*"]
preset = "default"
"""


@pytest.fixture()
def defs(tmp_path, monkeypatch):
    """Definitions over a file whose sets cover some data sets only, and a registered one."""
    from pwa_pipeline.orchestration.cli import main

    monkeypatch.setenv("PWA_DATASETS", str(tmp_path / "datasets.json"))
    monkeypatch.setenv("PWA_HPARAMS", str(tmp_path / "hp.toml"))
    (tmp_path / "hp.toml").write_text(HPARAMS)
    d = make_hure_vasak(n_samples=300, seed=3)
    pd.DataFrame({"u1": d.u_train[0][:, 0], "u2": d.u_train[0][:, 1], "y1": d.y_train[0][:, 0],
                  "y2": d.y_train[0][:, 1]}
                 ).to_csv(tmp_path / "mill.csv", index=False)
    assert main(["add-dataset", "mill", str(tmp_path / "mill.csv"), "--u", "u1", "u2",
                 "--y", "y1", "y2", "--na", "2"]) == 0
    return build_definitions(tmp_path / "hp.toml", tmp_path / "datasets.json")


def test_only_the_pairs_a_set_has_values_for_are_offered(defs):
    assert all_keys(partitions_of(defs)) == [
        "hure_vasak|paper", "hure_vasak|everywhere", "kuka_robot|robot_only",
        "kuka_robot|everywhere", "mill|everywhere"]
    with pytest.raises(ValueError, match=r"unknown partition 'hure_vasak\|robot_only'; the "
                                         r"partitions are \["):
        check_keys(partitions_of(defs), ["hure_vasak|robot_only"])


def test_every_offered_partition_builds_its_configuration(defs):
    settings = defs.resources["settings"]
    keys = all_keys(partitions_of(defs))
    for key in keys:
        part = PartitionKey.parse(key)
        dataset, hparams = part.dataset, part.hparams
        config = settings.configuration(hparams, dataset)
        assert (config.dataset, config.hparams) == (dataset, hparams)
        assert set(config.estimators) == {"pwa", "linear_arx", "subspace"}
    # the registered data set brings its orders to the "*" table
    assert settings.configuration("everywhere", "mill").pwa.na == 2


def test_every_partition_of_the_bundled_file_builds_its_configuration(monkeypatch, tmp_path):
    monkeypatch.delenv("PWA_HPARAMS", raising=False)
    monkeypatch.setenv("PWA_DATASETS", str(tmp_path / "datasets.json"))
    defs = build_definitions()
    keys = all_keys(partitions_of(defs))
    assert {PartitionKey.parse(k).dataset for k in keys} == set(DATASETS)
    assert "hure_vasak|robot" not in keys and "kuka_robot|robot" in keys
    for key in keys:
        part = PartitionKey.parse(key)
        dataset, hparams = part.dataset, part.hparams
        assert defs.resources["settings"].configuration(hparams, dataset).dataset == dataset
