"""Free-run scores in the literature's conventions (range-normalised single run, RMSE after a
window) against direct computations."""

import numpy as np
import pytest

from pwa_pipeline import LinearARX, evaluate, make_hure_vasak
from pwa_pipeline.scoring.conventions import CONVENTIONS, convention_scores, single_run_scores


@pytest.fixture(scope="module")
def fitted():
    train = make_hure_vasak(n_samples=1500, seed=3)
    test = [make_hure_vasak(n_samples=400, seed=s) for s in (11, 12)]
    model = LinearARX(na=1, nb=1).fit(train.u_train[0], train.y_train[0])
    return model, [t.u_train[0] for t in test], [t.y_train[0] for t in test]


def test_single_run_joins_the_experiments_and_scores_after_the_warmup(fitted):
    model, u, y = fitted
    ua, ya = np.vstack(u), np.vstack(y)
    sim = model.simulate(ua, ya[:10])
    err = np.sqrt(np.mean((sim[10:] - ya[10:]) ** 2, axis=0))
    np.testing.assert_allclose(single_run_scores(model, u, y, CONVENTIONS["range_single_run"]),
                               err / (ya.max(axis=0) - ya.min(axis=0)), rtol=1e-12)
    sim = model.simulate(ua, ya[:100])
    np.testing.assert_allclose(single_run_scores(model, u, y, CONVENTIONS["window_rmse"]),
                               np.sqrt(np.mean((sim[100:] - ya[100:]) ** 2, axis=0)),
                               rtol=1e-12)


def test_every_convention_is_reported_and_the_project_one_is_the_protocol(fitted):
    model, u, y = fitted
    scores = convention_scores(model, u, y)
    assert set(scores) == set(CONVENTIONS)
    assert scores["project"] == evaluate(model, u, y, warmup=10).mean("free_run")
    # range-normalised numbers are smaller than σ-normalised ones for these signals
    assert scores["range_single_run"] < scores["project"]
    with pytest.raises(ValueError, match="restarts at every experiment: use evaluate"):
        single_run_scores(model, u, y, CONVENTIONS["project"])
