"""The structure search (PWARX.auto): it finds the switching a machine was built with, falls
back to the linear model, and says what it did."""

import copy
import warnings

import numpy as np
import pytest

from pwa_pipeline import PWARX, LinearARX, make_hure_vasak
from pwa_pipeline.config import build_pwarx
from pwa_pipeline.pwa import SearchBudgetSpent, SearchTimeLimit, StructureSearch
from pwa_pipeline.pwa.search import search as structure_search
from pwa_pipeline.pwa.search.search import folds, split_experiments, windows
from pwa_pipeline.regressors import build_regressors

FAST = {"clustering": False, "max_variables": 1, "forms": ["level"]}


def siso_records(step, n_experiments: int, n: int, seed: int, u_low: float, start: int):
    """Records of a SISO machine y(k) = ``step(y, u, k)`` from rest, for k ≥ ``start``,
    driven by inputs held 10 samples at uniform levels on [``u_low``, 1], measured with
    noise of standard deviation 0.002."""
    rng = np.random.default_rng(seed)
    us, ys = [], []
    for _ in range(n_experiments):
        u = np.repeat(rng.uniform(u_low, 1, n // 10), 10)
        y = np.zeros(n)
        for k in range(start, n):
            y[k] = step(y, u, k)
        us.append(u[:, None])
        ys.append(y[:, None] + 0.002 * rng.standard_normal((n, 1)))
    return us, ys


def friction_machine(n_experiments: int = 12, n: int = 300, seed: int = 0,
                     friction: float = 0.08):
    """y(k) = 1.5 y(k−1) − 0.6 y(k−2) + 0.3 u(k−1) − f·sign(y(k−1) − y(k−2)) + noise: a
    mass with Coulomb friction, whose offset flips with the sign of the velocity."""
    return siso_records(lambda y, u, k: 1.5 * y[k - 1] - 0.6 * y[k - 2] + 0.3 * u[k - 1]
                        - friction * np.sign(y[k - 1] - y[k - 2]),
                        n_experiments, n, seed, u_low=-1, start=2)


@pytest.fixture(scope="module")
def friction_fit():
    u, y = friction_machine()
    return PWARX.auto(na=2, nb=1, **FAST).fit(u, y), (u, y)


def test_search_finds_the_velocity_sign_and_the_friction_offset(friction_fit):
    model, _ = friction_fit
    report = model.structure_search_
    (out,) = model.structure_fit_.outputs
    assert report.linear is False
    assert out.n_regions == 2
    # the one variable kept is the sign of the output's increment, as the machine was built
    (w,) = out.region_of.weights
    names = ["y1(k-1)", "y1(k-2)", "y1(k-3)", "u1(k-1)", "1"]
    assert dict(zip(names, w, strict=True)) == {"y1(k-1)": 1.0, "y1(k-2)": -1.0,
                                               "y1(k-3)": 0.0, "u1(k-1)": 0.0, "1": 0.0}
    # its two regions' constants are the friction, ±0.08, within noise
    thetas = model.structure_fit_.outputs[0].thetas()
    np.testing.assert_allclose(sorted(thetas[:, -1]), [-0.08, 0.08], atol=0.01)
    np.testing.assert_allclose(thetas[:, names.index("u1(k-1)")], [0.3, 0.3], atol=0.02)
    assert report.validation_nrmse < 0.8 * report.linear_nrmse
    chosen = report.table[report.table.stage == "chosen"]
    assert chosen.structure.item() == "level (2, 1), offset on [Δy1(k-1) > 0]" or \
        chosen.structure.item() == "level (2, 1), all on [Δy1(k-1) > 0]"
    assert chosen.outcome.item().startswith("chosen: beats the linear model")


def test_search_beats_linear_arx_on_unseen_experiments(friction_fit):
    model, (u, y) = friction_fit
    test_u, test_y = friction_machine(n_experiments=4, seed=99)
    linear = LinearARX(na=2, nb=1, affine=True).fit(u, y)
    from pwa_pipeline import evaluate

    pwa = evaluate(model, test_u, test_y, warmup=10).mean("free_run")
    lin = evaluate(linear, test_u, test_y, warmup=10).mean("free_run")
    assert pwa < 0.5 * lin


def test_state_space_export_of_a_searched_model_simulates_alike(friction_fit):
    model, (u, y) = friction_fit
    ss = model.to_state_space()
    np.testing.assert_allclose(ss.simulate(u[0], y[0][:10]), model.simulate(u[0], y[0][:10]),
                               rtol=0, atol=1e-8)
    assert ss.n_modes == 2


def saturating_machine(n_experiments: int = 10, n: int = 300, seed: int = 0):
    """y(k) = min(0.8 y(k−1) + 0.5 u(k−1), 1): a tank that overflows at level 1, whose
    boundary 0.8 y(k−1) + 0.5 u(k−1) = 1 is oblique (no threshold of one signal)."""
    return siso_records(lambda y, u, k: min(0.8 * y[k - 1] + 0.5 * u[k - 1], 1.0),
                        n_experiments, n, seed, u_low=0, start=1)


@pytest.fixture(scope="module")
def saturating_fit():
    u, y = saturating_machine()
    return PWARX.auto(na=1, nb=1, clustering=False).fit(u, y)


def test_an_oblique_boundary_is_found_at_the_hinge_of_its_pieces(saturating_fit):
    """The overflow's boundary is recovered within 2° of its direction (the threshold of
    the linear prediction alone is 27° off: drop the hinge step and this fails), with the
    two pieces the machine has, and the model beats the linear one by 20× on unseen
    experiments."""
    model = saturating_fit
    (out,) = model.structure_fit_.outputs
    assert out.n_regions == 2
    (w,) = out.region_of.weights  # over y1(k-1), y1(k-2), u1(k-1), 1
    truth = np.array([0.8, 0.0, 0.5, -1.0])
    cosine = abs(w @ truth) / np.linalg.norm(w) / np.linalg.norm(truth)
    assert np.degrees(np.arccos(min(cosine, 1.0))) < 2
    pieces = out.thetas()[np.argsort(out.thetas()[:, -1])]
    np.testing.assert_allclose(pieces, [[0.8, 0.0, 0.5, 0.0], [0.0, 0.0, 0.0, 1.0]],
                               atol=0.02)
    table = model.structure_search_.table
    kept = table[table.outcome == "kept for y1: the hinge of its two pieces"]
    assert len(kept) >= 1 and kept.structure.iloc[-1] in model.structures_[0]
    assert "hinge of y1: y1(k-1) + 0.593·u1(k-1)" in model.structures_[0]
    from pwa_pipeline import evaluate

    test_u, test_y = saturating_machine(n_experiments=4, seed=99)
    linear = LinearARX(na=1, nb=1, affine=True).fit(*saturating_machine())
    assert evaluate(model, test_u, test_y).mean("free_run") < \
        0.05 * evaluate(linear, test_u, test_y).mean("free_run")


def test_an_oblique_boundary_exports_to_state_space(saturating_fit):
    u, y = saturating_machine(n_experiments=1, seed=7)
    ss = saturating_fit.to_state_space()
    assert ss.n_modes == 2
    np.testing.assert_allclose(ss.simulate(u[0], y[0][:10]),
                               saturating_fit.simulate(u[0], y[0][:10]), rtol=0, atol=1e-8)


def soft_limit_machine(n_experiments: int = 8, n: int = 300, seed: int = 0):
    """y(k) = 0.8 y(k−1) + 0.5 u(k−1) − 0.6 max(0, y(k−1) − 1.2) + noise: a gain that
    falls continuously past a level (no jump)."""
    return siso_records(lambda y, u, k: 0.8 * y[k - 1] + 0.5 * u[k - 1]
                        - 0.6 * max(0.0, y[k - 1] - 1.2), n_experiments, n, seed, u_low=0,
                        start=1)


def test_the_search_bends_slopes_where_asked_for_continuous_switches():
    """With ``switches=["continuous"]`` the search keeps a hinge (its words say where the
    slopes bend, at a quantile knot: 1.11 against the truth's 1.2), and beats the linear
    model on unseen experiments by 3× (0.063 against 0.34)."""
    u, y = soft_limit_machine()
    model = PWARX.auto(na=1, nb=1, switches=["continuous"], **FAST).fit(u, y)
    (out,) = model.structure_fit_.outputs
    assert out.structure == "continuous"
    assert "continuous, slopes bend at [" in model.structures_[0]
    assert " = " in model.structures_[0] and " > " not in model.structures_[0]
    thetas = out.thetas()
    np.testing.assert_allclose(thetas[1] - thetas[0], out.p[-1] * out.hinges()[0], atol=1e-12)
    from pwa_pipeline import evaluate

    test_u, test_y = soft_limit_machine(n_experiments=4, seed=99)
    linear = LinearARX(na=1, nb=1, affine=True).fit(u, y)
    assert evaluate(model, test_u, test_y).mean("free_run") < \
        evaluate(linear, test_u, test_y).mean("free_run") / 3


def test_oblique_names_read_as_formulas():
    from pwa_pipeline.pwa.search.search import oblique_name

    names = ["y1(k-1)", "y1(k-2)", "u1(k-1)", "1"]
    assert oblique_name(np.array([0.8, 0.0, 0.5, -1.0]), names) == \
        "y1(k-1) + 0.625·u1(k-1) > 1.25"
    assert oblique_name(np.array([0.0, -2.0, 1.0, 1.0]), names) == \
        "-y1(k-2) + 0.5·u1(k-1) > -0.5"


def test_a_linear_machine_gets_the_linear_model_and_the_report_says_so():
    u, y = friction_machine(friction=0.0)
    model = PWARX.auto(na=2, nb=1, n_folds=5, **FAST).fit(u, y)
    report = model.structure_search_
    assert report.linear is True
    assert [o.structure for o in model.structure_fit_.outputs] == ["linear"]
    assert "Linear ARX: no switching structure beat it" in report.choice
    assert report.verdict == "linear kept (no switching structure beat it held out)"
    assert report.validation_nrmse == report.linear_nrmse
    # with the best switching candidate's number, the one the table lists: none was
    # shortlisted (none lowered the first block's error by min_gain), so the number is the
    # first block's, beside the linear model's there
    import re
    table = report.table
    assert table[table.stage == "cross-validated"].structure.tolist() == \
        ["level (2, 1), linear"]
    switching = table[table.stage.isin(["scheduled", "clustered", "refined"])
                      & ~table.structure.str.endswith("linear")]
    best = switching.loc[switching.validation_nrmse.idxmin()]
    found = re.search(r"The best switching candidate measured, (.+), had ([0-9.]+) on the "
                      r"first held-out block, where the refined linear model had ([0-9.]+) "
                      r"\(none lowered the error by min_gain", report.choice)
    assert found and found.group(1) == best.structure
    assert float(found.group(2)) == pytest.approx(best.validation_nrmse, rel=1e-3)
    first = table[(table.stage == "refined") & table.structure.str.endswith("linear")]
    assert float(found.group(3)) == pytest.approx(first.validation_nrmse.item(), rel=1e-3)
    assert float(found.group(2)) > (1 - 0.02) * float(found.group(3))


@pytest.mark.parametrize("n_folds", [1, 5])
def test_the_linear_fallback_wins_over_a_switching_structure_worse_on_held_out_data(
        monkeypatch, n_folds):
    """A switching structure the greedy search kept whose refined free run is worse than the
    linear model's, on the first block or over the folds, is not returned (drop the
    fallback and this fails)."""
    refined = structure_search._Search.refined
    cross_validated = structure_search._Search.cross_validated

    def worse(self, group, specs, models, label):
        cost, models, info = refined(self, group, specs, models, label)
        return (cost * 10 if label == "switching" else cost), models, info

    def worse_folds(self, group, models, main, refine):
        costs = cross_validated(self, group, models, main, refine)
        switching = any(models[j].region_of is not None for j in group)
        return [c * 10 for c in costs] if switching else costs

    monkeypatch.setattr(structure_search._Search, "refined", worse)
    monkeypatch.setattr(structure_search._Search, "cross_validated", worse_folds)
    u, y = friction_machine()
    model = PWARX.auto(na=2, nb=1, n_folds=n_folds, **FAST).fit(u, y)
    assert [o.structure for o in model.structure_fit_.outputs] == ["linear"]
    assert model.structure_search_.linear is True
    assert model.structure_search_.validation_nrmse == model.structure_search_.linear_nrmse


def test_one_record_is_split_in_time_and_a_short_one_is_refused():
    u, y = friction_machine(n_experiments=1, n=1200)
    model = PWARX.auto(na=2, nb=1, n_folds=1, **FAST).fit(u[0], y[0])
    assert "a single record: its last 240 of 1200 samples held out" in \
        model.structure_search_.choice
    # the candidates judged on that held-out part, not on held-out experiments
    chosen = model.structure_search_.table.query("stage == 'chosen'").outcome.item()
    assert "on the held-out part of the record" in chosen and "experiments" not in chosen
    with pytest.raises(ValueError, match="needs at least 2 experiments, or one record of at "
                                         "least 150 samples to split in time; got one record "
                                         "of 100 samples"):
        PWARX.auto(na=2, nb=1, **FAST).fit(u[0][:100], y[0][:100])


def test_split_holds_out_the_last_experiments():
    exps = [(np.zeros((5, 1)), np.full((5, 1), i)) for i in range(10)]
    fit, held, how = split_experiments(exps, 0.2, min_samples=3)
    assert [e[1][0, 0] for e in held] == [8, 9] and len(fit) == 8
    assert how == "experiments 9–10 of 10 held out"
    assert split_experiments(exps[:4], 0.2, min_samples=3)[2] == "experiment 4 of 4 held out"


def test_folds_hold_out_each_block_of_experiments_in_turn():
    exps = [(np.zeros((5, 1)), np.full((5, 1), i)) for i in range(10)]
    blocks, how = folds(exps, 0.2, n_folds=5, min_samples=3)
    assert [[e[1][0, 0] for e in held] for _, held in blocks] == \
        [[8, 9], [6, 7], [4, 5], [2, 3], [0, 1]]
    assert [e[1][0, 0] for e in blocks[2][0]] == [0, 1, 2, 3, 6, 7, 8, 9]
    assert (*blocks[0], how) == split_experiments(exps, 0.2, min_samples=3)
    assert len(folds(exps, 0.2, n_folds=3, min_samples=3)[0]) == 3
    assert len(folds(exps, 0.3, n_folds=9, min_samples=3)[0]) == 3  # 3 whole blocks of 3


def test_auto_folds_judge_on_a_thousand_held_out_samples_at_least():
    """``n_folds="auto"``: five blocks of a 1,000-sample record's 200 held-out samples, three
    of a 2,000-sample record's 400, one where the held-out experiments hold 1,000 samples;
    and the search's report says how many it judged on."""
    def record(n):
        return [(np.zeros((n, 1)), np.arange(n, dtype=float)[:, None])]

    assert len(folds(record(1000), 0.2, n_folds="auto", min_samples=30)[0]) == 5
    assert len(folds(record(2000), 0.2, n_folds="auto", min_samples=30)[0]) == 3
    assert len(folds(record(5000), 0.2, n_folds="auto", min_samples=30)[0]) == 1
    exps = [(np.zeros((500, 1)), np.zeros((500, 1))) for _ in range(10)]  # 2 held out
    assert len(folds(exps, 0.2, n_folds="auto", min_samples=30)[0]) == 1
    assert len(folds(exps[:5], 0.2, n_folds="auto", min_samples=30)[0]) == 2
    u, y = friction_machine(n_experiments=1, n=1200)
    report = PWARX.auto(na=2, nb=1, **FAST).fit(u[0], y[0]).structure_search_
    assert "its last 240 of 1200 samples held out; the shortlisted structures judged on 5 " \
        "held-out blocks in turn. " in report.choice
    chosen = report.table.query("stage == 'chosen'").outcome.item()
    assert chosen == "chosen: beats the linear model on the held-out blocks of 5 folds"
    assert "asked" not in report.choice


def test_more_folds_than_whole_blocks_are_said_so():
    u, y = friction_machine()
    report = PWARX.auto(na=2, nb=1, n_folds=9, **FAST).fit(u, y).structure_search_
    assert "the shortlisted structures judged on 6 held-out blocks in turn (n_folds=9 " \
        "asked: only 6 whole blocks of the held-out size fit in the data)" in report.choice


def test_folds_cut_one_record_in_blocks_fitting_what_lies_either_side():
    u, y = np.arange(1000.0)[:, None], np.arange(1000.0)[:, None]
    blocks, _ = folds([(u, y)], 0.2, n_folds=9, min_samples=30)
    spans = [[(int(e[1][0, 0]), int(e[1][-1, 0]) + 1) for e in fit + held]
             for fit, held in blocks]
    assert spans == [[(0, 800), (800, 1000)], [(0, 600), (800, 1000), (600, 800)],
                     [(0, 400), (600, 1000), (400, 600)], [(0, 200), (400, 1000), (200, 400)],
                     [(200, 1000), (0, 200)]]
    # a part shorter than min_samples is left out of the fit
    blocks, _ = folds([(u, y)], 0.3, n_folds=5, min_samples=150)
    assert [len(e[1]) for e in blocks[2][0]] == [600] and len(blocks[2][1][0][1]) == 300


def test_a_long_record_is_refined_on_windows_evenly_spread():
    y = np.arange(10_000.0)[:, None]
    exps = [(y[:6000], y[:6000]), (y[6000:9000], y[6000:9000]), (y[9000:], y[9000:])]
    assert windows(exps, 10_000, length=1000) is exps
    got = windows(exps, 4000, length=1000)
    assert [len(w[1]) for w in got] == [1000] * 4
    assert [int(w[1][0, 0]) for w in got] == [0, 3333, 6666, 9000]  # the last one shifted
    assert all(np.array_equal(w[0], w[1]) for w in got)  # u and y cut alike
    # experiments shorter than a window are taken whole, as many as the samples allow
    short = [(y[i:i + 300], y[i:i + 300]) for i in range(0, 6000, 300)]
    got = windows(short, 1500, length=1000)
    assert [len(w[1]) for w in got] == [300] * 5
    assert [int(w[1][0, 0]) for w in got] == [0, 1200, 2700, 4200, 5700]


def test_max_rows_fits_candidates_on_a_subsample_and_finds_the_same_structure(friction_fit):
    """Past ``max_rows`` the candidates are fitted on one regressor row in k and refined on
    windows; the friction offset is found all the same, its constants within noise (judged
    on one held-out block, as the fit on every row it is compared with)."""
    _, (u, y) = friction_fit
    full = PWARX.auto(na=2, nb=1, n_folds=1, **FAST).fit(u, y)
    model = PWARX.auto(na=2, nb=1, max_rows=1000, n_folds=1, **FAST).fit(u, y)
    report = model.structure_search_
    assert "candidates fitted on one in 3 of the 2970 regressor rows (max_rows), the " \
        "shortlisted ones on all and refined on 900 samples" in report.choice
    assert model.structures_ == full.structures_
    (out,) = model.structure_fit_.outputs
    np.testing.assert_allclose(sorted(out.thetas()[:, -1]), [-0.08, 0.08], atol=0.01)
    assert report.validation_nrmse < 1.05 * full.structure_search_.validation_nrmse


def test_the_choice_is_the_lowest_mean_over_the_folds_not_the_first_block(monkeypatch):
    """The friction offset, better than linear on the first block, made 20 times worse on
    every other fold: judged over 5 folds the linear model wins, judged on the first block
    alone the friction offset (a mutation choosing by the first block fails this)."""
    cross_validated = structure_search._Search.cross_validated

    def worse_elsewhere(self, group, models, main, refine):
        costs = cross_validated(self, group, models, main, refine)
        switching = any(models[j].region_of is not None for j in group)
        return costs[:1] + [c * 20 for c in costs[1:]] if switching else costs

    monkeypatch.setattr(structure_search._Search, "cross_validated", worse_elsewhere)
    u, y = friction_machine()
    five = PWARX.auto(na=2, nb=1, n_folds=5, **FAST).fit(u, y).structure_search_
    one = PWARX.auto(na=2, nb=1, n_folds=1, **FAST).fit(u, y).structure_search_
    assert five.linear and not one.linear
    rows = five.table[five.table.stage == "cross-validated"]
    switching = rows[~rows.structure.str.endswith("linear")]
    first = [float(t.split(": ")[1].split(", ")[0]) for t in rows.outcome]
    assert first[1] < first[0]  # the switching candidate was better on the first block
    assert "the shortlisted structures judged on 5 held-out blocks in turn." in five.choice
    for row in rows.itertuples():  # each row's figure is the mean of its folds
        figures = [float(x) for x in row.outcome.split(": ")[1].split(", ")]
        assert len(figures) == 5
        assert row.validation_nrmse == pytest.approx(np.mean(figures), rel=2e-3)
    assert five.validation_nrmse == rows.validation_nrmse.iloc[0] \
        < switching.validation_nrmse.min()


def test_time_limit_keeps_the_best_so_far_and_flags_it():
    u, y = friction_machine()
    with pytest.warns(SearchTimeLimit, match=r"time limit \(safety net\) of 1e-06 s"):
        model = PWARX.auto(na=2, nb=1, max_seconds=1e-6, **FAST).fit(u, y)
    report = model.structure_search_
    assert report.time_limited and "Time limit (safety net) of 1e-06 s reached" in \
        report.choice and "depends on the machine's speed" in report.choice
    assert np.isfinite(model.simulate(u[0], y[0])).all()


def test_a_time_limit_after_the_proposals_keeps_the_best_measured_candidate(monkeypatch):
    """The limit reached once the scheduled candidates are measured (simulated by setting
    the flag there): the friction offset, better than the linear reference on the held-out
    experiments, is kept unrefined rather than dropped for the linear model."""
    stage = structure_search._Search.scheduled_stage

    def then_late(self, *args, **kwargs):
        path = stage(self, *args, **kwargs)
        self.time_limited = True
        return path

    monkeypatch.setattr(structure_search._Search, "scheduled_stage", then_late)
    u, y = friction_machine()
    with pytest.warns(SearchTimeLimit):  # one block: the unrefined figure is the kept one
        model = PWARX.auto(na=2, nb=1, n_folds=1, **FAST).fit(u, y)
    report = model.structure_search_
    assert report.time_limited and report.linear is False
    assert report.verdict == ("switching structure kept: the search stopped at its time "
                              "limit, the best found kept")
    assert model.structure_fit_.outputs[0].n_regions == 2
    assert report.validation_nrmse < 0.8 * report.linear_nrmse
    unrefined = report.table[report.table.outcome == "not refined: time limit reached"]
    assert len(unrefined) >= 1 and unrefined.validation_nrmse.min() == \
        pytest.approx(report.validation_nrmse)


def test_a_spent_budget_keeps_the_best_candidate_measured_and_says_so():
    """FAST's linear stage measures 4 candidates (orders (1, 1) and (2, 1), decoupled and
    joint); a budget of 6 leaves two scheduled ones, the velocity sign's first in the pool:
    the friction offset is found and kept, and the report says the budget stopped it."""
    u, y = friction_machine()
    with pytest.warns(SearchBudgetSpent, match="budget of 6 candidates"):
        model = PWARX.auto(na=2, nb=1, max_candidates=6, **FAST).fit(u, y)
    report = model.structure_search_
    assert (report.n_candidates, report.budget_spent, report.time_limited) == (6, True, False)
    assert (report.table.stage == "scheduled").sum() == 2 + 1  # two measured, one kept
    assert "Budget of 6 candidates spent: the best measured kept" in report.choice
    assert report.verdict == ("switching structure kept: the search spent its budget of "
                              "candidates, the best found kept")
    (out,) = model.structure_fit_.outputs
    assert out.n_regions == 2 and out.region_of.weights[0][:2].tolist() == [1.0, -1.0]
    assert report.validation_nrmse < 0.8 * report.linear_nrmse


def test_a_spent_budget_on_a_linear_result_says_why_linear_was_kept():
    u, y = friction_machine()
    with pytest.warns(SearchBudgetSpent):
        model = PWARX.auto(na=2, nb=1, max_candidates=4, **FAST).fit(u, y)
    chosen = model.structure_search_.table.query("stage == 'chosen'").outcome.item()
    assert chosen == ("chosen: linear (no switching structure measured beat it on the held-out "
                      "blocks of 2 folds; stopped by the budget of 4 candidates)")
    assert "No switching candidate was measured (stopped by the budget of 4 candidates)." \
        in model.structure_search_.choice
    assert model.structure_search_.verdict == ("linear kept: the search spent its budget of "
                                               "candidates before a switching structure "
                                               "beat it")


def test_the_same_data_give_the_same_model_on_a_busy_machine():
    """The search stopped by its budget mid-way through the proposals gives the same model,
    to the bit, with both cores kept busy by other processes: it counts work, not
    seconds."""
    import subprocess
    import sys

    u, y = friction_machine()
    kwargs = {**FAST, "max_variables": 2, "max_candidates": 30}
    quiet = PWARX.auto(na=2, nb=1, **kwargs)
    with pytest.warns(SearchBudgetSpent):
        quiet.fit(u, y)
    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(3)]
    try:
        busy = PWARX.auto(na=2, nb=1, **kwargs)
        with pytest.warns(SearchBudgetSpent):
            busy.fit(u, y)
    finally:
        for b in burners:
            b.kill()
            b.wait()
    for model in (quiet, busy):
        assert model.structure_search_.n_candidates == 30
    np.testing.assert_array_equal(busy.thetas_, quiet.thetas_)
    assert busy.structures_ == quiet.structures_
    columns = ["stage", "structure", "validation_nrmse", "outcome"]
    assert busy.structure_search_.table[columns].equals(quiet.structure_search_.table[columns])


def test_the_search_is_never_worse_than_the_default_pwarx():
    """On the paper's system (section 5: four modes of a two-output machine) the search's
    own choice, per output clustered regions with a constant, refined, is worse on the
    held-out samples than the default PWARX(1, 1); the default is returned, with the
    paper's four modes, and the report says so. Drop the check (the default stage) and the
    search's choice, worse there, would be returned."""
    data = make_hure_vasak(n_samples=1500, seed=5)
    model = PWARX.auto(1, 1, max_variables=1).fit(data.u_train, data.y_train)
    report = model.structure_search_
    table = report.table
    default = table[table.stage == "default"]
    assert default.outcome.str.split(":").str[0].tolist() == [
        "default PWARX", "default PWARX with a constant"]
    searched = table[table.stage == "searched"]
    assert len(searched) == 2  # one per output: the search's own choice was decoupled
    assert report.validation_nrmse == default.validation_nrmse.iloc[0] \
        < searched.validation_nrmse.mean()
    chosen = table[table.stage == "chosen"]
    assert len(chosen) == 1 and chosen.outcome.item().startswith("chosen: the default PWARX")
    assert "The default PWARX (level (1, 1), clustered (4 regions)) beats the search's " \
        "choice on the held-out blocks of 4 folds" in report.choice
    assert model.structures_ == ["level (1, 1), clustered (4 regions)"] * 2
    # φ of the search holds y(k-2) and the constant too, at zero; on the others each of the
    # paper's four modes is found within 0.05
    names = ["y1(k-1)", "y1(k-2)", "y2(k-1)", "y2(k-2)", "u1(k-1)", "u2(k-1)", "1"]
    used = [names.index(n) for n in ("y1(k-1)", "y2(k-1)", "u1(k-1)", "u2(k-1)")]
    assert np.all(np.delete(model.thetas_, used, axis=1) == 0)
    found = model.thetas_[:, used]
    error = np.abs(found[:, None] - data.truth.thetas[None]).max(axis=(2, 3))
    assert model.n_submodels_ == 4 and error.min(axis=0).max() < 0.05


@pytest.mark.parametrize("kwargs, message", [
    ({"forms": ["levels"]}, r"forms must be a non-empty list of \['level', 'velocity'\]"),
    ({"couplings": []}, "couplings must be a non-empty list"),
    ({"max_variables": 9}, "max_variables"),
    ({"switches": ["hinge"]},
     r"switches must be a non-empty list of \['offset', 'all', 'continuous'\]"),
    ({"n_folds": "five"}, r"'n_folds' parameter of StructureSearch must be an int in the "
                          r"range \[1, inf\) or a str among \{'auto'\}"),
])
def test_bad_search_parameters_are_named(kwargs, message):
    u, y = friction_machine(n_experiments=3, n=100)
    with pytest.raises(ValueError, match=message):
        PWARX.auto(na=2, nb=1, **kwargs).fit(u, y)


def test_the_search_refuses_structures_it_chooses_itself():
    u, y = friction_machine(n_experiments=3, n=100)
    with pytest.raises(ValueError, match="leave form, refinement out"):
        PWARX.auto(na=2, nb=1).set_params(form="velocity",
                                           refinement=StructureSearch().refinement_step()
                                           ).fit(u, y)
    with pytest.raises(ValueError, match="needs affine=True"):
        PWARX.auto(na=2, nb=1).set_params(affine=False).fit(u, y)
    with pytest.raises(ValueError, match="na >= 1 and nb >= 1"):
        PWARX.auto(na=0, nb=1).fit(u, y)


def test_preset_auto_in_the_hyper_parameter_file():
    model = build_pwarx({"preset": "auto", "na": 3, "nb": 2, "search": {"max_seconds": 60}})
    assert (model.na, model.nb, model.affine) == (3, 2, True)
    assert model.search.max_seconds == 60
    with pytest.raises(ValueError, match="preset 'auto' fits a constant term"):
        build_pwarx({"preset": "auto", "affine": False})
    with pytest.raises(ValueError, match=r"unknown search parameter\(s\) \['max_second'\]"):
        build_pwarx({"preset": "auto", "search": {"max_second": 60}})


def test_the_report_lists_every_candidate_with_its_outcome(friction_fit):
    model, _ = friction_fit
    table = model.structure_search_.table
    assert list(table.columns) == ["stage", "outputs", "structure", "regions",
                                   "validation_nrmse", "outcome", "seconds"]
    assert table.seconds.is_monotonic_increasing
    assert set(table.stage) >= {"linear", "scheduled", "refined", "chosen"}
    # every candidate variable was tried with both switches
    scheduled = table[(table.stage == "scheduled") & (table.outcome == "tried")]
    assert scheduled.structure.str.contains("offset on").sum() == \
        scheduled.structure.str.contains("all on").sum() > 5
    summary = model.structure_search_.summary()
    assert summary.outcome.str.startswith("kept").sum() == 1
    # judged on two held-out blocks (n_folds="auto": 600 held-out samples), each
    # shortlisted structure's row with the figure of each block is among those that decided
    folds = table[table.stage == "cross-validated"]
    assert len(folds) >= 2 and folds.index.isin(summary.index).all()
    assert folds.outcome.str.fullmatch(r"mean of 2 folds: [0-9.]+, [0-9.]+").all()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert len(summary) < len(table)


def test_refit_fits_the_chosen_regions_on_every_training_experiment(friction_fit):
    model, (u, y) = friction_fit
    refit = PWARX.auto(na=2, nb=1, refit=True, refinement="none", **FAST).fit(u, y)
    (out,) = refit.structure_fit_.outputs
    np.testing.assert_array_equal(out.region_of.weights,
                                  model.structure_fit_.outputs[0].region_of.weights)
    # least squares in the same regions on all twelve experiments, held-out ones included
    everything = copy.deepcopy(out).fit(*_rows(u, y)).p
    np.testing.assert_allclose(out.p, everything, rtol=1e-10)
    without_held_out = copy.deepcopy(out).fit(*_rows(u[:10], y[:10])).p
    assert not np.allclose(out.p, without_held_out, rtol=1e-6)


def _rows(u, y):
    """φ rows (3 output lags, 1 input lag, the constant) and the output of experiments."""
    reg = build_regressors(list(zip(u, y, strict=True)), 3, 1, True)
    return reg.phi, reg.target[:, 0]


def test_a_diverging_candidate_is_listed_and_never_chosen(monkeypatch):
    """A candidate whose held-out free run blows up is recorded as diverged and skipped."""
    model_of = structure_search._Search.model

    def unstable_offsets(self, j, spec, coupling):
        om = model_of(self, j, spec, coupling)
        if spec.switch == "offset":  # y(k) ≈ 3 y(k−1): every offset candidate diverges
            om.p = om.p.copy()
            om.p[0] = 3.0
        return om

    monkeypatch.setattr(structure_search._Search, "model", unstable_offsets)
    u, y = friction_machine()
    model = PWARX.auto(na=2, nb=1, refinement="none", **FAST).fit(u, y)
    table = model.structure_search_.table
    offsets = table[(table.stage == "scheduled") & table.structure.str.contains("offset on")]
    assert len(offsets) > 5 and (offsets.outcome == "diverged").all()
    assert np.isinf(offsets.validation_nrmse).all()
    assert [o.structure for o in model.structure_fit_.outputs] == ["all"]


def test_the_search_says_its_progress_a_line_per_stage(caplog):
    u, y = friction_machine()
    with caplog.at_level("INFO", logger=structure_search.SEARCH_LOG):
        PWARX.auto(na=2, nb=1, **FAST).fit(u, y)
    lines = [r.getMessage() for r in caplog.records if r.name == structure_search.SEARCH_LOG]
    assert lines[0].startswith("structure search: linear reference decoupled (y1 level (2, 1)")
    assert lines[1].startswith("structure search: y1: scheduled regions and clusters (")
    import re
    assert lines[2].startswith("structure search: y1: level (2, 1)") \
        and re.search(r"; \d+ of at most 2000 candidates, \d+ s\)$", lines[2])
