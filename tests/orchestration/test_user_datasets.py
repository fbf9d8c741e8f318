"""The user's own data sets: registration checks, the split, the CLI and the partitions."""


import dagster as dg
import numpy as np
import pandas as pd
import pytest

from pwa_pipeline.config import BUNDLED_HPARAMS
from pwa_pipeline.datasets import make_hure_vasak
from pwa_pipeline.datasets.user import UserDataset
from pwa_pipeline.orchestration.definitions import build_definitions, partitions_of
from pwa_pipeline.orchestration.partitions import all_keys, runnable_keys
from pwa_pipeline.orchestration.registry import DatasetRegistry

from ._resources import run_resources

COLUMNS = dict(u=("u1", "u2"), y=("y1", "y2"))


@pytest.fixture(scope="module")
def table():
    """The paper's system (N = 1200) as a user's table: four experiments of 300 rows."""
    d = make_hure_vasak(n_samples=1200, seed=7)
    u, y = d.u_train[0], d.y_train[0]
    return pd.DataFrame({"t": np.arange(1200) * 0.01, "run": np.repeat(list("abcd"), 300),
                         "u1": u[:, 0], "u2": u[:, 1], "y1": y[:, 0], "y2": y[:, 1]})


@pytest.fixture()
def csv(tmp_path, table):
    path = tmp_path / "plant.csv"
    table.to_csv(path, index=False)
    return path


@pytest.fixture()
def registry(tmp_path):
    return DatasetRegistry(tmp_path / "reg" / "datasets.json")


def test_registration_round_trips_and_splits_by_experiment(registry, csv, table):
    spec = UserDataset("plant", csv, **COLUMNS, experiment="run", time="t",
                       test_experiments=("b",))
    data = registry.add(spec)
    assert registry.names() == ["plant"] and registry.get("plant") == spec
    assert [len(u) for u in data.u_train] == [300, 300, 300] and len(data.u_test) == 1
    held = table[table.run == "b"]
    np.testing.assert_array_equal(data.u_test[0], held[["u1", "u2"]].to_numpy())
    np.testing.assert_array_equal(data.y_train[1], table[table.run == "c"][["y1", "y2"]])
    assert registry.remove("plant") == spec.path and registry.names() == []


def test_default_split_holds_out_the_last_experiments_or_the_end_of_one_record(
        registry, tmp_path, csv, table):
    by_exp = UserDataset("p", csv, **COLUMNS, experiment="run", test_fraction=0.5).load()
    assert len(by_exp.u_train) == 2 and by_exp.n_test == 600
    np.testing.assert_array_equal(by_exp.y_test[1], table[table.run == "d"][["y1", "y2"]])
    path = tmp_path / "one.parquet"
    table.to_parquet(path)
    one = registry.add(UserDataset("one", path, **COLUMNS), one_record=True)  # the last 25 %
    assert (one.n_train, one.n_test) == (900, 300)
    np.testing.assert_array_equal(one.u_test[0], table[["u1", "u2"]].to_numpy()[900:])


def test_an_id_in_two_separate_blocks_is_two_experiments(tmp_path, table):
    # run a, then b, then a again: the second block of a does not follow the first
    runs = np.repeat(["a", "b", "a", "c"], 300)
    path = tmp_path / "blocks.csv"
    table.assign(run=runs, t=np.arange(1200) % 300).to_csv(path, index=False)
    data = UserDataset("blocks", path, **COLUMNS, experiment="run", time="t",
                       test_experiments=("c",)).load()
    assert [len(u) for u in data.u_train] == [300, 300, 300]
    np.testing.assert_array_equal(data.u_train[2], table[["u1", "u2"]].to_numpy()[600:900])
    one = UserDataset("blocks", path, **COLUMNS, experiment="run", test_experiments=("a#2",))
    np.testing.assert_array_equal(one.load().u_test[0], data.u_train[2])
    both = UserDataset("blocks", path, **COLUMNS, experiment="run", test_experiments=("a",))
    assert [len(u) for u in both.load().u_test] == [300, 300]  # an id holds out every block
    table.assign(run=np.repeat(["a", "b", "a", "a#2"], 300)).to_csv(path, index=False)
    with pytest.raises(ValueError, match=r"blocks.csv: experiment id 'a' appears in separate "
                       r"blocks of rows, and 'a#2', the name of its block 2, is another id"):
        UserDataset("blocks", path, **COLUMNS, experiment="run").load()


@pytest.mark.parametrize("edit, kwargs, message", [
    (None, dict(u=("u1", "speed")), r"no column\(s\) \['speed'\]"),
    (lambda df: df.assign(y2=df["y2"].astype(object).where(df.index != 17, "abc")), {},
     r"column 'y2' has 1 non-numeric.*'abc' at row 17"),
    (lambda df: df.assign(u1=df["u1"].where(df.index != 40)), {}, "column 'u1'.*at row 40"),
    (lambda df: df.assign(t=df["t"].where(df.index != 11, df.loc[10, "t"])), {},
     "time column 't' is repeated in experiment 'a': row 11 follows row 10"),
    (lambda df: df.assign(t=df["t"].where(df.index != 320, 0.0)), {},
     r"time column 't' is decreasing \(the rows are not sorted by time\) in experiment 'b'"),
    (None, dict(test_experiments=("z",)), r"test experiment\(s\) \['z'\] are not in column"),
    (None, dict(test_experiments=tuple("abcd")), "none is left for training"),
    (lambda df: df.drop(index=range(303, 600)), {},
     "experiment 'b' has 3 sample.*needs at least 5 with na = 4"),
    (lambda df: df.drop(index=range(1, 1200)), dict(experiment=None, na=1,
                                                                  test_fraction=0.5),
     "has 0 sample"),
])
def test_a_bad_file_is_refused_with_one_message_and_nothing_registered(
        registry, tmp_path, table, edit, kwargs, message):
    df = table if edit is None else edit(table)
    path = tmp_path / "bad.csv"
    df.to_csv(path, index=False)
    args = dict(**COLUMNS, experiment="run", time="t", na=4, nb=1, test_experiments=("d",))
    args.update(kwargs)
    if "test_fraction" in kwargs or args["experiment"] is None:
        args.pop("test_experiments")
    with pytest.raises(ValueError, match=message):
        registry.add(UserDataset("bad", path, **args))
    assert registry.names() == [] and not registry.path.exists()


def test_too_few_rows_for_the_local_sets_and_clashing_names_are_refused(registry, tmp_path,
                                                                        table):
    path = tmp_path / "short.csv"
    table.iloc[:40].to_csv(path, index=False)  # 20 training samples
    half = dict(**COLUMNS, test_fraction=0.5)
    with pytest.raises(ValueError, match="18 regressor rows, fewer than .* n_rho = 3d = 24"):
        registry.add(UserDataset("short", path, **half, na=2, nb=2))
    with pytest.raises(ValueError, match="'kuka_robot' is a built-in data set"):
        UserDataset("kuka_robot", path, **COLUMNS)
    with pytest.raises(ValueError, match="invalid data set name 'my plant'"):
        UserDataset("my plant", path, **COLUMNS)
    registry.add(UserDataset("p", path, **half))
    with pytest.raises(ValueError, match="already registered"):
        registry.add(UserDataset("p", path, **half, nb=2))
    assert registry.get("p").na == 1


_RULE = (r"MLflow's metric names, which hold it, allow only letters, digits, '_', '-', '\.' "
         r"and spaces, at most 100 characters")


@pytest.mark.parametrize(("kwargs", "message"), [
    (dict(u=("temp(degC)", "u2")),
     r"input column 'temp\(degC\)' cannot be used: " + _RULE + r"; rename it \(e.g. "
     r"'temp_degC'\)"),
    (dict(y=("y1", "valve%")), r"output column 'valve%' cannot be used: .*e.g. 'valve'"),
    (dict(y=("a:b", "y2")), r"output column 'a:b' cannot be used"),
    (dict(y=("y/1", "y2")), r"output column 'y/1' cannot be used"),
    (dict(y=("y\nsystem(1)", "y2")), r"output column 'y\\nsystem\(1\)' cannot be used"),
    (dict(y=("y" * 101, "y2")), r"output column 'yyy.* cannot be used: .*at most 100"),
    (dict(name="p" * 300), r"invalid data set name 'ppp.*': use letters, digits, '_' and '-' "
                           r"only, at most 64 characters"),
    (dict(na=50), r"na must be an integer from 1 to 20 \(lags per channel\), got 50"),
    (dict(nb=True), r"nb must be an integer from 1 to 20 \(lags per channel\), got True"),
])
def test_names_and_orders_that_would_fail_later_are_refused_at_registration(tmp_path, kwargs,
                                                                           message):
    """What a run would fail on minutes later (MLflow's metric names, a file name too long,
    an order beyond any local set) is refused when the data set is registered."""
    with pytest.raises(ValueError, match=message):
        UserDataset(**{"name": "plant", "path": tmp_path / "plant.csv", **COLUMNS, **kwargs})


def test_the_column_names_allowed_are_metric_names_mlflow_takes(tmp_path, mlflow_template):
    """Every name the rule lets through, in the longest metric key built from it, is logged
    by MLflow; the names it refuses are those MLflow refuses (or, ':' and '/', would make
    another key or a path on some platforms)."""
    import shutil

    from mlflow.tracking import MlflowClient

    from pwa_pipeline.orchestration.reporting import PER_OUTPUT

    names = ["Joint 1.torque-Nm", "µm_x", "y" * 100, "T_amb"]
    spec = UserDataset("plant", tmp_path / "plant.csv", u=("u1",), y=tuple(names))
    db = tmp_path / "mlflow.db"
    shutil.copy(mlflow_template, db)
    client = MlflowClient(tracking_uri=f"sqlite:///{db}")
    run = client.create_run(client.create_experiment("names"))
    for name in spec.y:
        client.log_metric(run.info.run_id, f"{PER_OUTPUT}free_run_nrmse_{name}", 0.5)
    assert len(client.get_run(run.info.run_id).data.metrics) == len(names)


def test_the_cli_registers_lists_and_removes(tmp_path, csv, capsys, monkeypatch):
    from pwa_pipeline.orchestration.cli import main

    monkeypatch.setenv("PWA_DATASETS", str(tmp_path / "datasets.json"))
    assert main(["add-dataset", "plant", str(csv), "--u", "u1", "u2", "--y", "y1", "y2",
                 "--experiment", "run", "--time", "t", "--test-experiments", "d"]) == 0
    out = capsys.readouterr().out
    assert "training : 3 experiment(s), 900 samples" in out and "plant|default" in out
    assert main(["add-dataset", "plant2", str(csv), "--u", "u1", "--y", "y9",
                 "--experiment", "run"]) == 2
    assert "error: plant.csv has no column(s) ['y9']" in capsys.readouterr().err
    assert main(["list-datasets"]) == 0
    out = capsys.readouterr().out
    assert "1 registered data set(s)" in out and "test experiments ['d']" in out
    assert main(["partitions"]) == 0
    assert "plant|default" in capsys.readouterr().out.split()
    assert main(["remove-dataset", "plant"]) == 0
    assert main(["remove-dataset", "plant"]) == 2
    assert "no data set 'plant'" in capsys.readouterr().err


def test_a_file_of_several_experiments_is_refused_without_its_experiment_column(
        tmp_path, table, capsys, monkeypatch):
    """A file whose run-id column or restarting time says it holds several experiments is
    refused without --experiment, in one line naming the column to pass; --experiment or
    --no-experiment registers it; a single record registers without either."""
    from pwa_pipeline.orchestration.cli import main

    monkeypatch.setenv("PWA_DATASETS", str(tmp_path / "datasets.json"))
    restarting = table.assign(t=np.tile(np.arange(300) * 0.01, 4))
    files = {"runs": restarting, "times": restarting.drop(columns="run"),
             "single": table.drop(columns="run")}
    for name, frame in files.items():
        frame.to_csv(tmp_path / f"{name}.csv", index=False)

    def add(name: str, *extra: str) -> int:
        return main(["add-dataset", name, str(tmp_path / f"{name}.csv"), "--u", "u1", "u2",
                     "--y", "y1", "y2", *extra])

    assert add("runs") == 2
    assert capsys.readouterr().err == (
        "pwa-pipeline add-dataset: error: runs.csv looks like several experiments, not one "
        "record: column 'run' looks like experiment ids (4 values: 'a', 'b', 'c', …) and "
        "time column 't' goes back 3 time(s), first at row 300; pass --experiment run, or "
        "--no-experiment if it is one record\n")
    assert add("times", "--time", "t") == 2
    assert capsys.readouterr().err == (
        "pwa-pipeline add-dataset: error: times.csv looks like several experiments, not one "
        "record: time column 't' goes back 3 time(s), first at row 300; pass --experiment "
        "COLUMN naming the column of experiment ids (add one to the file if it has none), "
        "or --no-experiment if it is one record\n")
    assert DatasetRegistry(tmp_path / "datasets.json").names() == []
    assert add("runs", "--experiment", "run", "--time", "t") == 0
    assert "training : 3 experiment(s), 900 samples" in capsys.readouterr().out
    assert add("times", "--no-experiment") == 0
    assert "training : 1 experiment(s), 900 samples" in capsys.readouterr().out
    assert add("single", "--time", "t") == 0
    assert DatasetRegistry(tmp_path / "datasets.json").names() == ["runs", "single", "times"]


def test_a_registered_data_set_is_a_partition_that_runs(tmp_path, csv, mlflow_template):
    registry = DatasetRegistry(tmp_path / "datasets.json")
    registry.add(UserDataset("plant", csv, **COLUMNS, experiment="run", time="t"))
    defs = build_definitions(BUNDLED_HPARAMS, registry.path)
    partitions = partitions_of(defs)
    assert "plant|default" in all_keys(partitions)  # the paper's values are per data set:
    assert "plant|paper" not in all_keys(partitions)  # no partition
    settings = defs.resources["settings"]
    keys, skipped = runnable_keys(partitions, settings, ("paper", "default"))
    assert "plant|default" in keys and "plant|paper" not in keys
    assert "has no values for 'plant'" in skipped["plant|paper"]
    resources = run_resources(tmp_path, mlflow_template, settings)
    result = dg.materialize(list(defs.assets), partition_key="plant|default",
                            resources=resources)
    model = result.asset_value("pwa_model")
    assert result.success and model.n_submodels_ >= 2 and (model.na, model.nb) == (1, 1)
    scores = result.asset_value("comparison")
    assert set(scores["method"]) == {"pwa", "linear_arx", "subspace"}
    # the file disappears: its partitions are skipped, saying why
    csv.unlink()
    keys, skipped = runnable_keys(partitions, settings)
    assert not any(k.startswith("plant|") for k in keys)
    assert "plant.csv is missing" in skipped["plant"]


def test_hparams_tables_for_unregistered_data_sets_fail_at_load(tmp_path):
    path = tmp_path / "h.toml"
    path.write_text('[s.plant]\nna = 1\nnb = 1\n[s."*"]\nna = 2\n')
    with pytest.raises(ValueError, match=r"\['na'\] come from each data set's registration"):
        build_definitions(path, tmp_path / "datasets.json")
    path.write_text("[s.plant]\nna = 1\nnb = 1\n")
    with pytest.raises(ValueError, match=r"tables for unknown data set\(s\) \['plant'\]"):
        build_definitions(path, tmp_path / "datasets.json")


def test_the_docs_example_registers_the_bundled_table(tmp_path, monkeypatch, capsys):
    import shlex
    from pathlib import Path

    from pwa_pipeline.orchestration.cli import main

    root = Path(__file__).resolve().parents[2]
    readme = (root / "docs" / "your-data.md").read_text()
    start = readme.index("python -m pwa_pipeline add-dataset plant")
    command = readme[start:readme.index("\n", readme.index("\\\n", start) + 2)]
    args = shlex.split(command.replace("\\\n", " "))[3:]
    monkeypatch.setenv("PWA_DATASETS", str(tmp_path / "datasets.json"))
    monkeypatch.chdir(root)
    assert main(args) == 0
    assert "training : 3 experiment(s), 1,800 samples" in capsys.readouterr().out
    assert DatasetRegistry(tmp_path / "datasets.json").get("plant").test_experiments == ("r4",)


def test_a_broken_hyper_parameter_file_registers_nothing(tmp_path, csv, capsys, monkeypatch):
    from pwa_pipeline.orchestration.cli import main

    monkeypatch.setenv("PWA_DATASETS", str(tmp_path / "datasets.json"))
    broken = tmp_path / "hp.toml"
    broken.write_text("[default.\n")
    monkeypatch.setenv("PWA_HPARAMS", str(broken))
    args = ["add-dataset", "plant", str(csv), "--u", "u1", "u2", "--y", "y1", "y2",
            "--experiment", "run"]
    assert main(args) == 2
    assert f"error: {broken} is not valid TOML" in capsys.readouterr().err
    assert DatasetRegistry(tmp_path / "datasets.json").names() == []
    monkeypatch.setenv("PWA_HPARAMS", str(BUNDLED_HPARAMS))
    assert main(args) == 0  # the retry registers it: nothing was left half-done


def test_units_given_at_registration_reach_the_figures_and_the_listing(tmp_path, csv, capsys,
                                                                        monkeypatch):
    """``--units NAME=UNIT …`` is stored with the registration, listed, and labels the axes
    of the data set's figures (``y1 [deg]``); a column without one stays bare."""
    from pwa_pipeline import LinearARX
    from pwa_pipeline.orchestration.cli import main
    from pwa_pipeline.plotting import PredictionDisplay
    from pwa_pipeline.scoring.evaluation import evaluate

    monkeypatch.setenv("PWA_DATASETS", str(tmp_path / "datasets.json"))
    assert main(["add-dataset", "plant", str(csv), "--u", "u1", "u2", "--y", "y1", "y2",
                 "--experiment", "run", "--units", "y1=deg", "u2=N·m"]) == 0
    assert "units    : u2=N·m y1=deg" in capsys.readouterr().out
    assert main(["list-datasets"]) == 0
    assert "    units = u2=N·m y1=deg" in capsys.readouterr().out.splitlines()
    registry = DatasetRegistry(tmp_path / "datasets.json")
    assert registry.get("plant").units == {"y1": "deg", "u2": "N·m"}
    data = registry.get("plant").load()
    assert data.units == {"y1": "deg", "u2": "N·m"}
    model = LinearARX(na=1, nb=1).fit(data.u_train, data.y_train)
    ev = evaluate(model, data.u_test, data.y_test, warmup=10, output_names=data.y_names)
    fig = PredictionDisplay.from_evaluation(ev, data, 10, context="plant | set default | linear ARX").figure_
    assert [ax.get_ylabel() for ax in fig.axes] == ["y1 [deg]", "y2"]
    assert [data.label(n) for n in data.u_names] == ["u1", "u2 [N·m]"]
    # the units change no fit or score: the digest is that of the data without them
    bare = UserDataset("plant", csv, **COLUMNS, experiment="run").load()
    assert bare.digest == data.digest and bare.units == {}


@pytest.mark.parametrize("units, message", [
    (["speed=m/s"], "a unit is given for 'speed', which is not an input (--u) or output (--y) "
                    "column; those are ['u1', 'u2', 'y1', 'y2']"),
    (["run=s"], "a unit is given for 'run', which is not an input (--u) or output (--y) "
                "column"),
    (["y1"], "--units 'y1' is not NAME=UNIT (e.g. y1=deg)"),
    (["y1="], "--units 'y1=' is not NAME=UNIT (e.g. y1=deg)"),
    (["=deg"], "--units '=deg' is not NAME=UNIT (e.g. y1=deg)"),
    (["y1=deg", "y1=rad"], "--units gives 'y1' twice (y1=deg, y1=rad)"),
])
def test_bad_units_are_refused_with_one_line_naming_them(tmp_path, csv, capsys, monkeypatch,
                                                         units, message):
    from pwa_pipeline.orchestration.cli import main

    monkeypatch.setenv("PWA_DATASETS", str(tmp_path / "datasets.json"))
    assert main(["add-dataset", "plant", str(csv), "--u", "u1", "u2", "--y", "y1", "y2",
                 "--experiment", "run", "--units", *units]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"pwa-pipeline add-dataset: error: {message}")
    assert err.count("\n") == 1  # one line
    assert DatasetRegistry(tmp_path / "datasets.json").names() == []


def test_a_registry_written_before_units_loads_without_them(tmp_path, csv, capsys,
                                                           monkeypatch):
    """An entry without ``units`` (registries written before they existed) loads with none,
    is listed as such, and can be replaced by one with units."""
    import json

    from pwa_pipeline.orchestration.cli import main

    path = tmp_path / "datasets.json"
    entry = {"name": "plant", "path": str(csv), "u": ["u1", "u2"], "y": ["y1", "y2"],
             "experiment": "run", "time": "t", "test_experiments": ["d"],
             "test_fraction": None, "na": 1, "nb": 1, "affine": False}
    path.write_text(json.dumps({"version": 1, "datasets": {"plant": entry}}))
    registry = DatasetRegistry(path)
    spec = registry.get("plant")
    assert spec.units == {} and spec.test_experiments == ("d",)
    assert spec.load().units == {}
    monkeypatch.setenv("PWA_DATASETS", str(path))
    assert main(["list-datasets"]) == 0
    assert "    units = none" in capsys.readouterr().out.splitlines()
    assert main(["add-dataset", "plant", str(csv), "--u", "u1", "u2", "--y", "y1", "y2",
                 "--experiment", "run", "--time", "t", "--test-experiments", "d",
                 "--units", "y2=V", "--replace"]) == 0
    assert registry.get("plant").units == {"y2": "V"}
    assert json.loads(path.read_text())["datasets"]["plant"]["units"] == {"y2": "V"}


def test_an_entry_registered_before_a_rule_is_listed_and_refused_not_fatal(tmp_path, csv,
                                                                           capsys,
                                                                           monkeypatch):
    """An entry written before the column-name rule (``temp(degC)``) leaves the rest of the
    registry usable: listed with the rule it breaks and the fix, skipped by a run of every
    data set, refused in one line by a run of its own, and removable."""
    import json

    from pwa_pipeline.orchestration.cli import main

    path = tmp_path / "datasets.json"
    good = UserDataset("plant", csv, **COLUMNS, experiment="run").describe()
    old = {**good, "name": "old", "u": ["temp(degC)", "u2"]}
    path.write_text(json.dumps({"version": 1, "datasets": {"plant": good, "old": old}}))
    monkeypatch.setenv("PWA_DATASETS", str(path))
    assert main(["list-datasets"]) == 0
    out = capsys.readouterr().out
    assert "2 registered data set(s)" in out and "  plant: " in out
    line = next(s for s in out.splitlines() if s.startswith("  old: "))
    assert "input column 'temp(degC)' cannot be used" in line
    assert "a column renamed in" in line and "add-dataset NAME" in line and "--replace" in line
    assert "remove-dataset old" in line
    defs = build_definitions(BUNDLED_HPARAMS, path)
    keys, skipped = runnable_keys(partitions_of(defs), defs.resources["settings"])
    assert "plant|default" in keys and not any(k.startswith("old|") for k in keys)
    assert "input column 'temp(degC)' cannot be used" in skipped["old"]
    for variable, value in (("PWA_HPARAMS", BUNDLED_HPARAMS), ("PWA_PIPELINE_HOME", tmp_path),
                            ("DAGSTER_HOME", tmp_path / "home")):
        monkeypatch.setenv(variable, str(value))  # stores of this test's own, if it ran
    monkeypatch.delenv("MLFLOW_TRACKING_URI", raising=False)
    assert main(["run", "--partition", "old|default"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("pwa-pipeline run: error: data set 'old' registered in ")
    assert "input column 'temp(degC)' cannot be used" in err and err.count("\n") == 1
    assert main(["remove-dataset", "old"]) == 0
    assert DatasetRegistry(path).names() == ["plant"]
