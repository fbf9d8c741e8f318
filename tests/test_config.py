import os

import numpy as np
import pandas as pd
import pytest

from pwa_pipeline import PWARX, LinearARX, SubspaceSS
from pwa_pipeline.config import BUNDLED_HPARAMS, HParamsFile
from pwa_pipeline.datasets import DATASETS, MEASURED
from pwa_pipeline.methods import METHODS
from pwa_pipeline.pwa import ClusterCentres, RefinedSubModels
from pwa_pipeline.scoring.comparison import table1


def _write(tmp_path, text):
    path = tmp_path / "hp.toml"
    path.write_text(text)
    return path


def test_every_set_builds_every_method_for_every_dataset():
    hp = HParamsFile()
    assert hp.path == BUNDLED_HPARAMS and {"paper", "default"} <= set(hp.sets)
    for name in hp.sets:
        for ds in DATASETS:
            if not hp.covers(name, ds):
                # the robot's structure is for the robot only; the paper's and the
                # variants' sets give no values for the measured benchmarks
                assert name == "robot" or ds in MEASURED, (name, ds)
                assert name not in ("default", "output_error"), (name, ds)
                continue
            cfg = hp.configuration(name, ds)
            assert list(cfg.estimators) == list(METHODS)
            assert isinstance(cfg.pwa, PWARX) and isinstance(cfg.estimators["linear_arx"], LinearARX)
            sub = cfg.estimators["subspace"]
            # the measured benchmarks' warm-up is their own window (5 and 20 samples)
            official = MEASURED[ds][0].convention.warmup if ds in MEASURED else 10
            assert isinstance(sub, SubspaceSS) and sub.warmup == cfg.warmup == official
            assert cfg.estimators["linear_arx"].na == cfg.pwa.na
    paper = hp.configuration("paper", "kuka_robot").pwa.get_params()
    # the paper's values are given (it has no rule for them), its steps are the paper's
    assert None not in (paper["local_models__n_rho"], paper["clustering__eps"],
                        paper["clustering__min_pts"])
    assert isinstance(paper["submodels"], ClusterCentres) and not paper["clustering__unit_free"]
    assert hp.configuration("default", "kuka_robot").estimators["subspace"].order == 12


def test_nested_keys_set_step_parameters(tmp_path):
    path = _write(tmp_path, """
[fine.hure_vasak]
na = 2
clustering.eps = 0.25
submodels.n_search = 0
regions.C = 10.0
[baselines.hure_vasak]
warmup = 5
subspace.horizon = 4
""")
    cfg = HParamsFile(path).configuration("fine", "hure_vasak")
    p = cfg.pwa.get_params()
    assert (p["na"], p["nb"], p["clustering__eps"], p["submodels__n_search"], p["regions__C"]) \
        == (2, 1, 0.25, 0, 10.0)
    assert isinstance(p["submodels"], RefinedSubModels) and cfg.warmup == 5
    assert cfg.estimators["subspace"].get_params() == {"horizon": 4, "order": None, "warmup": 5,
                                                       "refit": "none", "max_radius": 0.9995}
    assert cfg.params("pwa")["clustering__eps"] == 0.25 and cfg.params("pwa")["hparams"] == "fine"


def test_the_robot_structure_is_read_for_the_pwa_model_and_its_linear_baseline():
    cfg = HParamsFile().configuration("robot", "kuka_robot")
    p = cfg.pwa.get_params()
    assert (p["na"], p["nb"], p["affine"], p["form"], p["outputs"]) == (2, 2, True, "velocity",
                                                                       "decoupled")
    assert p["scheduling__switch"] == "select" and p["scheduling__variables"] == "own_increment"
    assert p["refinement__max_iter"] == 60 and p["refinement__validation_fraction"] == 0.1
    assert p["refinement__one_step_weight"] == 0.001 and p["refinement__patience"] == 8
    linear = cfg.estimators["linear_arx"].get_params()
    assert (linear["form"], linear["outputs"], linear["refinement__max_iter"],
            linear["refinement__one_step_weight"]) == ("velocity", "decoupled", 60, 0.001)
    assert cfg.estimators["subspace"].refit == "simulation"
    assert cfg.params("pwa")["scheduling"] == "SignScheduling"


def test_user_scheduling_variables_are_read_as_tables(tmp_path):
    path = _write(tmp_path, """
[own.hure_vasak]
affine = true
scheduling.switch = "offset"
scheduling.variables = [{ "y1(k-1)" = 1.0, "u1(k-1)" = -0.5 }]
""")
    scheduling = HParamsFile(path).configuration("own", "hure_vasak").pwa.scheduling
    assert scheduling.variables == [{"y1(k-1)": 1.0, "u1(k-1)": -0.5}]
    assert scheduling.switch == "offset"


def test_unknown_names_are_reported():
    hp = HParamsFile()
    with pytest.raises(KeyError, match="unknown hyper-parameter set 'nope'.*known: \\['paper'"):
        hp.configuration("nope", "hure_vasak")
    with pytest.raises(KeyError, match="no values for data set 'mars'"):
        hp.configuration("paper", "mars")


@pytest.mark.parametrize(("text", "message"), [
    ("[a.hure_vasak]\nclustering.epsilon = 0.1\n",
     r"hp.toml, \[a.hure_vasak\]: Invalid parameter 'epsilon'"),
    ("[a.hure_vasak]\nclustering.eps = \"0.1\"\n",
     r"\[a.hure_vasak\]: The 'eps' parameter of DBSCANClustering must be"),
    ("[a.hure_vasak]\nlocal_models.ridge = -1\n",
     r"'ridge' parameter of LocalLeastSquares must be a float in the range \[0"),
    ("[a.hure_vasak]\n[baselines.hure_vasak]\nwarmup = -3\n",
     r"'warmup' parameter of SubspaceSS must be an int in the range \[1"),
    ("[a.hure_vasak]\npreset = \"fast\"\n", "unknown preset 'fast'"),
    ("[a.hure_vasak]\npreset = \"paper\"\nclustering.eps = 0.1\n",
     "preset 'paper' needs local_models.n_rho, clustering.min_pts"),
    ("[a.hure_vasak]\nna = \n", r"hp.toml is not valid TOML: .*line 2"),
    ("[\"eps0.1\".hure_vasak]\n", r"invalid hyper-parameter set name 'eps0.1'"),
    ("[a.\"../x\"]\n", r"invalid data set name '../x'"),
    ("[a.hure_vasak]\nform = \"speed\"\n",
     r"\[a.hure_vasak\]: The 'form' parameter of PWARX must be a str among"),
    ("[a.hure_vasak]\nscheduling.switch = \"sometimes\"\n",
     r"\[a.hure_vasak\]: The 'switch' parameter of SignScheduling must be a str among"),
    ("[a.hure_vasak]\nscheduling.sign = 1\n",
     r"unknown scheduling parameter\(s\) \['sign'\]; it has \['min_gain', 'switch'"),
    ("[a.hure_vasak]\nscheduling = 3\n", r"scheduling must be a table, e.g. scheduling.switch"),
    ("[a.hure_vasak]\n[baselines.hure_vasak]\nsubspace.refit = \"always\"\n",
     r"'refit' parameter of SubspaceSS must be a str among"),
])
def test_bad_files_are_refused_when_read(tmp_path, text, message):
    with pytest.raises(ValueError, match=message):
        HParamsFile(_write(tmp_path, text))


@pytest.mark.parametrize(("text", "message"), [
    ("[a.hure_vasak]\nna = true\n",
     r"\[a.hure_vasak\]: na = true is a boolean, which na does not take \(Python would "
     r"read it as 1\)"),
    ("[a.hure_vasak]\nclustering.min_pts = true\n",
     "clustering.min_pts = true is a boolean"),
    ("[a.hure_vasak]\n[baselines.hure_vasak]\nwarmup = true\n",
     r"\[baselines.hure_vasak\]: warmup = true is a boolean"),
    ("[a.hure_vasak]\n[baselines.hure_vasak]\nsubspace.order = true\n",
     r"\[baselines.hure_vasak\]: subspace.order = true is a boolean"),
    ("[a.hure_vasak]\nna = 50\n",
     r"\[a.hure_vasak\]: na = 50 is above 20, the largest this file accepts \(lags per "
     r"channel"),
    ("[a.hure_vasak]\nlocal_models.n_rho = 100000000000000000\n",
     "local_models.n_rho = 100000000000000000 is above 10000"),
    ("[a.hure_vasak]\nclustering.min_pts = 1000000000\n",
     "clustering.min_pts = 1000000000 is above 10000"),
    ("[a.hure_vasak]\nclustering.min_pts = 5000\n",
     r"clustering.min_pts = 5000 is above clustering.max_clustered = 3000: DBSCAN clusters "
     r"at most max_clustered local models"),
    ("[a.hure_vasak]\n[baselines.hure_vasak]\nsubspace.order = 100000\n",
     r"\[baselines.hure_vasak\]: subspace.order = 100000 is above 100"),
    ("[a.hure_vasak]\n[baselines.\"*\"]\nsubspace.horizon = 1000\n",
     r"\[baselines.\*\]: subspace.horizon = 1000 is above 100"),
    ("[a.hure_vasak]\n[baselines.hure_vasak]\nwarmup = 1000000\n",
     r"warmup = 1000000 is above 10000"),
    ('[a."*"]\nlocal_models.n_rho = 20000\n',
     r'\[a.\*\]: local_models.n_rho = 20000 is above 10000'),
])
def test_booleans_and_absurd_sizes_are_refused_when_read(tmp_path, text, message):
    """TOML's true is not the count 1, and a count beyond its stated limit fails at load, not
    after minutes of a run."""
    with pytest.raises(ValueError, match=message):
        HParamsFile(_write(tmp_path, text))


def test_the_limits_let_the_largest_sane_values_through(tmp_path):
    hp = HParamsFile(_write(tmp_path, "[a.hure_vasak]\nna = 20\nnb = 20\naffine = true\n"
                                      "local_models.n_rho = 10000\nclustering.min_pts = 3000\n"
                                      "[baselines.hure_vasak]\nwarmup = 10000\n"
                                      "subspace.order = 100\nsubspace.horizon = 100\n"))
    config = hp.configuration("a", "hure_vasak")
    assert (config.pwa.na, config.pwa.affine, config.warmup) == (20, True, 10000)
    assert config.estimators["subspace"].order == 100

def test_missing_file_names_the_path(tmp_path):
    with pytest.raises(FileNotFoundError, match="hyper-parameter file not found: .*none.toml"):
        HParamsFile(tmp_path / "none.toml")


def test_table1_layout_follows_the_method_registry():
    rows = [{"dataset": "d", "method": m, "mode": "free_run", "output": o, "nrmse": 0.1 * i,
             "r2": 1 - 0.01 * i} for i, m in enumerate(reversed(list(METHODS)))
            for o in ("q1", "mean")]
    t = table1(pd.DataFrame(rows), "d", "free_run", list(METHODS))
    assert list(t.index) == ["q1", "mean"]
    assert list(t.columns[::2]) == [f"{m} NRMSE" for m in METHODS]
    assert t.loc["q1", "linear_arx R² %"] == pytest.approx(99.0)
    assert np.isclose(t.loc["mean", "pwa NRMSE"], 0.2)
    with_sets = pd.DataFrame(rows).assign(hparams="paper")
    assert table1(with_sets, "d", "free_run", list(METHODS)).columns[0] == "pwa (paper) NRMSE"
    with pytest.raises(ValueError, match=r"unknown method\(s\) \['lstm'\]"):
        table1(pd.DataFrame(rows).replace("subspace", "lstm"), "d", "free_run", list(METHODS))


@pytest.mark.parametrize(("text", "message"), [
    ('[baselines.hure_vasak]\nwarmpu = 3\nbogus = "x"\n',
     r"\[baselines.hure_vasak\]: unknown key\(s\) \['bogus', 'warmpu'\]; its keys are "
     r"\['subspace', 'warmup'\]"),
    ("[baselines]\nhure_vasak = 3\n", r"\[baselines.hure_vasak\]: must be a table"),
])
def test_a_baselines_table_with_unknown_keys_is_refused_naming_them(tmp_path, text, message):
    path = tmp_path / "hp.toml"
    path.write_text("[a.hure_vasak]\n\n" + text)
    with pytest.raises(ValueError, match=message) as info:
        HParamsFile(path)
    assert str(path) in str(info.value)


def test_a_baselines_table_for_an_unknown_data_set_is_refused(tmp_path):
    from pwa_pipeline.orchestration.definitions import build_definitions

    path = tmp_path / "hp.toml"
    path.write_text("[a.hure_vasak]\n\n[baselines.kuka_robto]\nwarmup = 3\n")
    with pytest.raises(ValueError, match=r"unknown data set\(s\) \['kuka_robto'\]"):
        build_definitions(path)


@pytest.mark.parametrize(("content", "message"), [
    (b"s1 = 3\n", r"s1 must be a table \[<set>.<dataset>\] of parameters"),
    (b"[s1]\nhure_vasak = 3\n", r"s1.hure_vasak must be a table"),
    (b"", r"has no hyper-parameter set"),
    (b"[baselines.hure_vasak]\nwarmup = 5\n", r"has no hyper-parameter set"),
    (b"\xff\xfe\x00", r"is not valid TOML: 'utf-8' codec can't decode"),
    (b'["../x".hure_vasak]\n', r"invalid hyper-parameter set name '../x'"),
    (b'[s1."../y"]\n', r"invalid data set name '../y'"),
])
def test_a_malformed_hyper_parameter_file_is_refused_naming_it(tmp_path, content, message):
    path = tmp_path / "hp.toml"
    path.write_bytes(content)
    with pytest.raises(ValueError, match=message) as info:
        HParamsFile(path)
    assert str(path) in str(info.value)


def test_the_partitions_command_says_what_is_wrong_in_one_line(tmp_path, monkeypatch, capsys):
    from pwa_pipeline.orchestration.cli import main

    path = tmp_path / "hp.toml"
    path.write_text("s1 = 3\n")
    monkeypatch.setenv("PWA_HPARAMS", str(path))
    assert main(["partitions"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"pwa-pipeline partitions: error: {path}: s1 must be a table")
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_the_hyper_parameter_file_is_read_once_and_again_when_it_changes(tmp_path):
    from pwa_pipeline.config import load_hparams

    path = tmp_path / "h.toml"
    path.write_text('[a.hure_vasak]\npreset = "default"\nna = 1\nnb = 1\n')
    first = load_hparams(path)
    assert load_hparams(path) is first  # unchanged: the same reading
    path.write_text('[a.hure_vasak]\npreset = "default"\nna = 2\nnb = 1\n')
    os.utime(path, ns=(path.stat().st_atime_ns, path.stat().st_mtime_ns + 10**9))
    changed = load_hparams(path)
    assert changed is not first and changed.configuration("a", "hure_vasak").pwa.na == 2
    path.write_text("[a.hure_vasak\n")
    os.utime(path, ns=(path.stat().st_atime_ns, path.stat().st_mtime_ns + 2 * 10**9))
    with pytest.raises(ValueError, match="is not valid TOML"):
        load_hparams(path)
