"""The simulated machines of the tuning set: deterministic, shaped and named as documented,
bounded, and with their switching physics active in a useful share of the samples."""

import numpy as np
import pytest

from pwa_pipeline.datasets import MACHINES, Dataset, make_machine
from pwa_pipeline.datasets.machines import REPORTING_FIRST_SEED, TUNING_SEEDS

SHAPES = {"two_link_arm": (["tau1", "tau2"], ["q1", "q2"]),
          "two_tank": (["u"], ["h1", "h2"]),
          "dc_motor": (["u"], ["w_motor", "w_load"])}
#: Physical bounds of the clean outputs: joint angles (deg), levels (m), speeds (rad/s).
BOUNDS = {"two_link_arm": (-270.0, 180.0), "two_tank": (0.0, 0.5), "dc_motor": (-500.0, 500.0)}


@pytest.fixture(scope="module")
def data() -> dict[str, Dataset]:
    return {name: make_machine(name, 8, 300, seed=3, n_test=2) for name in MACHINES}


def test_seed_policy_keeps_tuning_and_reporting_apart():
    assert REPORTING_FIRST_SEED not in TUNING_SEEDS
    assert max(TUNING_SEEDS) < REPORTING_FIRST_SEED


@pytest.mark.parametrize("name", list(SHAPES))
def test_same_seed_same_data_other_seed_or_held_out_differs(name, data):
    again = make_machine(name, 8, 300, seed=3, n_test=2)
    for a, b in zip(data[name].u_train + data[name].y_test, again.u_train + again.y_test,
                    strict=True):
        np.testing.assert_array_equal(a, b)
    other = make_machine(name, 8, 300, seed=4).u_train
    held = make_machine(name, 8, 300, seed=3, n_test=8).u_test
    for different in (other, held):
        assert not np.allclose(np.stack(different), np.stack(data[name].u_train))
    # the held-out stream does not depend on how many training experiments are drawn
    np.testing.assert_array_equal(make_machine(name, 3, 300, seed=3, n_test=2).u_test[1],
                                  data[name].u_test[1])


@pytest.mark.parametrize("name", list(SHAPES))
def test_shapes_names_units_and_bounds(name, data):
    d = data[name]
    u_names, y_names = SHAPES[name]
    assert (d.name, d.u_names, d.y_names) == (name, u_names, y_names)
    assert set(d.units) == set(u_names + y_names)
    assert len(d.u_train) == len(d.y_train) == len(d.truth.y_clean_train) == 8
    assert len(d.u_test) == len(d.truth.y_clean_test) == 2
    for u, y, clean in zip(d.u_train, d.y_train, d.truth.y_clean_train, strict=True):
        assert u.shape == (300, len(u_names)) and y.shape == clean.shape == (300, len(y_names))
        assert np.isfinite(u).all() and np.isfinite(y).all()
        low, high = BOUNDS[name]
        assert clean.min() >= low and clean.max() <= high
    for flag in d.truth.flags_train.values():
        assert len(flag) == 8 and all(f.shape == (300,) and f.dtype == bool for f in flag)
    noise = np.stack(d.y_train) - np.stack(d.truth.y_clean_train)
    np.testing.assert_allclose(noise.std(axis=(0, 1)), d.truth.noise_std, rtol=0.1)


def test_noise_free_on_request():
    d = make_machine("two_tank", 2, 100, seed=0, noise_std=None)
    np.testing.assert_array_equal(np.stack(d.y_train), np.stack(d.truth.y_clean_train))


def test_arm_moves_both_ways_in_every_joint(data):
    flags = data["two_link_arm"].truth.flags_train
    for joint in (1, 2):
        up, down = np.stack(flags[f"q{joint}_dot>0"]), np.stack(flags[f"q{joint}_dot<0"])
        # every experiment has the joint sliding in both directions, a large share overall
        assert (up.mean(axis=1) > 0.05).all() and (down.mean(axis=1) > 0.05).all()
        assert up.mean() > 0.15 and down.mean() > 0.15
        assert 0.3 < (up | down).mean() < 0.9  # and sticking the rest of the time


def test_tank_overflows_and_valve_saturates_in_a_share_of_samples(data):
    flags = data["two_tank"].truth.flags_train
    for name in ("overflow", "valve_saturated"):
        assert 0.05 < np.stack(flags[name]).mean() < 0.95
    clean = np.stack(data["two_tank"].truth.y_clean_train)
    assert np.isclose(clean[..., 0][np.stack(flags["overflow"])], 0.5).all()  # at the rim


def test_motor_crosses_dead_zone_and_backlash(data):
    d = data["dc_motor"]
    for name in ("dead_zone", "backlash_gap"):
        assert 0.05 < np.stack(d.truth.flags_train[name]).mean() < 0.95
    u = np.concatenate(d.u_train)[:, 0]
    assert (u > 2.5).any() and (u < -2.5).any()  # driven through the dead zone both ways


def test_bad_arguments_raise_clear_errors():
    with pytest.raises(ValueError, match="unknown machine 'lathe'; known: two_link_arm"):
        make_machine("lathe")
    with pytest.raises(ValueError, match="n_experiments"):
        make_machine("dc_motor", 0)
    with pytest.raises(ValueError, match="n_samples"):
        make_machine("dc_motor", 2, 1)
    with pytest.raises(ValueError, match="noise_std"):
        make_machine("dc_motor", 2, 10, noise_std=-1.0)
