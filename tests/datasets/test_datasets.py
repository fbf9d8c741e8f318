import numpy as np
import pandas as pd
import pytest

from pwa_pipeline.datasets import Dataset, load_kuka, load_table, make_hure_vasak
from pwa_pipeline.datasets.simulated import HURE_VASAK_THETAS, hure_vasak_mode


def test_simulation_follows_eq_11_to_14(sim_30db):
    u, y = sim_30db.u_train[0], sim_30db.y_train[0]
    clean, modes = sim_30db.truth.y_clean_train[0], sim_30db.truth.modes_train[0]
    assert u.shape == y.shape == (4000, 2)
    assert u[:, 0].min() >= -4 and u[:, 0].max() <= 6
    assert u[:, 1].min() >= -2 and u[:, 1].max() <= 4
    # noise-free dynamics: y(k) = θ_λᵀ φ(k), λ from y(k-1) (eq. 12)
    phi = np.column_stack([clean[:-1], u[:-1]])
    np.testing.assert_array_equal(modes[1:], hure_vasak_mode(clean[:-1]))
    pred = np.einsum("nd,ndm->nm", phi, HURE_VASAK_THETAS[modes[1:]])
    np.testing.assert_allclose(pred, clean[1:], atol=1e-12)
    # eq. (14) holds exactly per output
    e = y - clean
    snr = 10 * np.log10((clean**2).sum(0) / (e**2).sum(0))
    np.testing.assert_allclose(snr, [30.0, 30.0])
    assert set(np.unique(modes)) == {0, 1, 2, 3}


def test_simulation_is_seeded():
    a, b = make_hure_vasak(200, seed=3), make_hure_vasak(200, seed=3)
    np.testing.assert_array_equal(a.y_train[0], b.y_train[0])
    assert not np.array_equal(a.y_train[0], make_hure_vasak(200, seed=4).y_train[0])


def test_missing_robot_file_names_path_and_download(tmp_path):
    with pytest.raises(FileNotFoundError, match=rf"not found at {tmp_path}.*DOI 10.26204/DATA/5"):
        load_kuka(tmp_path)


def test_robot_data_is_cut_into_606_sample_experiments(robot):
    assert len(robot.u_train) == 66 and len(robot.u_test) == 6
    assert all(u.shape == (606, 6) for u in robot.u_train[:-1] + robot.u_test)
    assert robot.u_train[-1].shape == (598, 6)
    assert sum(len(y) for y in robot.y_train) == 39988


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_user_tables_round_trip(tmp_path, suffix):
    df = pd.DataFrame({"run": [1, 1, 1, 2, 2], "force": [0.1, 0.2, 0.3, 0.4, 0.5],
                       "pos": [1.0, 2.0, 3.0, 4.0, 5.0]})
    path = tmp_path / f"data{suffix}"
    df.to_csv(path, index=False) if suffix == ".csv" else df.to_parquet(path)
    data = load_table(path, ["force"], ["pos"], experiment_column="run")
    assert isinstance(data, Dataset) and (data.name, data.u_names, data.y_names) == (
        "data", ["force"], ["pos"])
    assert [a.shape for a in data.u_train] == [(3, 1), (2, 1)] and data.u_test == []
    np.testing.assert_array_equal(data.y_train[1][:, 0], [4.0, 5.0])
    with pytest.raises(ValueError, match=r"no column\(s\) \['speed'\]"):
        load_table(path, ["speed"], ["pos"])
    with pytest.raises(ValueError, match="unsupported file type '.txt'"):
        (tmp_path / "x.txt").write_text("a")
        load_table(tmp_path / "x.txt", ["a"], ["b"])


def test_a_data_sets_digest_changes_with_any_part_of_it_and_travels_with_it():
    """What the pipeline's caches key on in place of the data: equal for equal contents,
    another for a sample changed by 1e-12, another split, other names or other truth."""
    import dataclasses
    import pickle

    from pwa_pipeline.datasets import load_dataset

    data = load_dataset("hure_vasak")
    same = pickle.loads(pickle.dumps(dataclasses.replace(data)))
    assert same.digest == data.digest and len(data.digest) == 24
    y = data.y_test[0].copy()
    y[5, 1] += 1e-12
    u = np.concatenate(data.u_train)
    half = len(u) // 2
    others = [
        dataclasses.replace(data, y_test=[y]),
        *(dataclasses.replace(data, u_train=np.split(u, [cut]),
                              y_train=np.split(np.concatenate(data.y_train), [cut]))
          for cut in (half, half + 1)),  # the same samples in other experiments
        dataclasses.replace(data, y_names=data.y_names[::-1]),
        dataclasses.replace(data, truth=None),
        dataclasses.replace(data, name="other")]
    digests = {data.digest, *(d.digest for d in others)}
    assert len(digests) == 1 + len(others)
    # computed once, then stored with the data set (the raw_benchmark asset's pickle)
    stored = pickle.loads(pickle.dumps(data))
    assert stored.__dict__["digest"] == data.digest
