"""Issue 10: piecewise-constant (held) inputs, as from a PLC, a PRBS or a step test."""

import numpy as np
import pytest

from benchmarks.held_inputs import held_hure_vasak
from pwa_pipeline import PWARX
from pwa_pipeline.datasets.simulated import HURE_VASAK_THETAS
from pwa_pipeline.pwa import DBSCANClustering, LocalLeastSquares

from ..conftest import max_param_error


@pytest.mark.parametrize("seed", [101, 102])  # not among the seeds the default was tuned on
def test_held_inputs_give_every_mode_without_an_error(seed):
    u, y = held_hure_vasak(4000, seed)
    m = PWARX(na=1, nb=1).fit(u, y)
    assert m.steps_["local_models"].n_degenerate_ > 500  # many local sets lie inside one hold
    assert not (m.steps_["clustering"].labels_[m.steps_["local_models"].degenerate_] >= 0).any()
    assert m.n_submodels_ == 4 and max_param_error(m.thetas_, HURE_VASAK_THETAS) < 0.2


def test_too_few_usable_local_sets_say_why():
    u, y = held_hure_vasak(400, 3, hold=(60, 80))
    phi = np.column_stack([y[:-1], u[:-1]])
    local = LocalLeastSquares(n_rho=12).fit(phi, y[1:])
    with pytest.raises(ValueError, match=r"\d+ of 399 local sets are degenerate .*held constant"):
        # more than the usable local sets, no more than all of them (else min_pts is the fault)
        DBSCANClustering(min_pts=399 - local.n_degenerate_ + 1).fit(local, y[1:])
