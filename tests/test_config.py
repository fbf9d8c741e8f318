import numpy as np
import pandas as pd
import pytest

from pwa_pipeline.comparison import METHODS, fit_method, table1
from pwa_pipeline.config import get_hparams, set_names
from pwa_pipeline.datasets import DATASETS
from pwa_pipeline.identification import PWARX


def test_every_set_builds_models_for_every_dataset():
    names = set_names()
    assert {"paper", "default"} <= set(names) and len(names) >= 3
    for name in names:
        for ds in DATASETS:
            hp = get_hparams(name, ds)
            assert isinstance(hp.pwa_model(), PWARX)
            assert hp.subspace_model().order == hp.baselines["subspace_order"]
    paper = get_hparams("paper", "kuka_robot").pwa_model()
    assert (paper.n_rho, paper.eps, paper.min_pts, paper.na) == (61, 8.0, 22, 2)


def test_unknown_names_are_reported():
    with pytest.raises(KeyError, match="unknown hyper-parameter set 'nope'; known: \\['paper'"):
        get_hparams("nope", "hure_vasak")
    with pytest.raises(KeyError, match="no values for data set 'mars'"):
        get_hparams("paper", "mars")
    with pytest.raises(ValueError, match="unknown method 'lstm'"):
        fit_method("lstm", get_hparams("paper", "hure_vasak"), None, None)


def test_table1_layout():
    rows = [{"dataset": "d", "method": m, "mode": "free_run", "output": o, "nrmse": 0.1 * i,
             "r2": 1 - 0.01 * i} for i, m in enumerate(METHODS) for o in ("q1", "mean")]
    t = table1(pd.DataFrame(rows), "d", "free_run")
    assert list(t.index) == ["q1", "mean"]
    assert t.columns[0] == "pwa_paper NRMSE" and t.columns[1] == "pwa_paper R² %"
    assert t.loc["q1", "linear_arx R² %"] == pytest.approx(98.0)
    assert np.isclose(t.loc["mean", "subspace NRMSE"], 0.3)
