"""Bad input that used to give a silently wrong result is refused with a message naming it."""

import numpy as np
import pandas as pd
import pytest
from scipy.io import savemat

from pwa_pipeline import PWARX, LinearARX, SubspaceSS, evaluate, load_kuka, load_table
from pwa_pipeline._validation import as_experiments, as_signal


def _arx_data(n=200, seed=0):
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(n, 1))
    y = np.zeros((n, 1))
    for k in range(1, n):
        y[k] = 0.5 * y[k - 1] + u[k - 1]
    return u, y


# 1. load_table: NaN experiment ids, non-numeric and missing u/y cells


def test_table_rows_without_experiment_id_are_refused(tmp_path):
    run = np.where(np.arange(20) % 2 == 0, 1.0, np.nan)  # 10 of 20 rows have no id
    df = pd.DataFrame({"run": run, "force": np.arange(20.0), "pos": np.arange(20.0)})
    df.to_csv(tmp_path / "d.csv", index=False)
    with pytest.raises(ValueError, match=r"d\.csv: column 'run' is empty in 10 row\(s\) \(first: row 1\)"):
        load_table(tmp_path / "d.csv", ["force"], ["pos"], experiment_column="run")


def test_table_non_numeric_cell_is_named_by_row_and_column(tmp_path):
    path = tmp_path / "d.csv"
    path.write_text("run,force,pos\n1,0.1,1\n1,0.2,2\n1,0.3,3\n2,abc,4\n2,0.5,5\n")
    with pytest.raises(ValueError, match=r"d\.csv: column 'force' has 1 non-numeric, missing or infinite "
                                         r"value\(s\) \(first: 'abc' at row 3\)"):
        load_table(path, ["force"], ["pos"], experiment_column="run")


def test_table_missing_cell_is_named_by_row_and_column(tmp_path):
    path = tmp_path / "d.csv"
    path.write_text("force,pos\n0.1,1\n0.2,2\n0.3,\n0.4,\n")
    with pytest.raises(ValueError, match=r"d\.csv: column 'pos' has 2 non-numeric, missing or infinite "
                                         r"value\(s\) \(first: NaN or empty at row 2\)"):
        load_table(path, ["force"], ["pos"])


# 2. masked arrays


def test_masked_entries_are_refused_and_an_unmasked_masked_array_is_accepted():
    u, y = _arx_data()
    mask = np.zeros(y.shape, bool)
    mask[[17, 40, 41]] = True
    y_masked = np.ma.masked_array(y, mask=mask)
    with pytest.raises(ValueError, match=r"y has 3 masked value\(s\) \(first at sample 17, "
                                         r"channel 0\); a masked sample cannot be fitted"):
        LinearARX(1, 1).fit(u, y_masked)
    u_1d = np.ma.masked_invalid(np.r_[np.zeros(5), np.nan, np.zeros(4)])
    with pytest.raises(ValueError, match=r"u has 1 masked value\(s\) \(first at sample 5, channel 0\)"):
        as_experiments(u_1d, np.zeros(10))
    fitted = LinearARX(1, 1).fit(np.ma.masked_array(u), np.ma.masked_array(y, mask=False))
    np.testing.assert_allclose(fitted.theta_, LinearARX(1, 1).fit(u, y).theta_)


# 3. complex input


@pytest.mark.parametrize("imag", [0.5, 0.0])
def test_complex_signals_are_refused(imag):
    u, y = _arx_data()
    with pytest.raises(ValueError, match=r"u is complex \(dtype complex128\); a real signal is needed"):
        LinearARX(1, 1).fit(u + 1j * imag, y)
    with pytest.raises(ValueError, match=r"y is complex"):
        as_signal([1.0, 2.0 + 1j * imag], "y")


# 4. evaluate: warmup and output_names


@pytest.mark.parametrize(("warmup", "shown"), [(-3, "-3"), (0, "0"), (2.5, "2.5"), (True, "True")])
def test_evaluate_refuses_a_warmup_below_one_or_not_an_integer(warmup, shown):
    u, y = _arx_data()
    model = LinearARX(1, 1).fit(u, y)
    with pytest.raises(ValueError, match=rf"warmup must be an integer >= 1, got {shown}$"):
        evaluate(model, u, y, warmup=warmup)
    assert evaluate(model, u, y, warmup=np.int64(1)).mean("one_step") < 1e-9


@pytest.mark.parametrize(("names", "message"), [
    ([], r"output_names has 0 name\(s\) but y has 2 output\(s\)"),
    (["a"], r"output_names has 1 name\(s\) but y has 2 output\(s\)"),
    (["a", "b", "c"], r"output_names has 3 name\(s\) but y has 2 output\(s\)"),
    (["mean", "q2"], r"output_names must be distinct and not 'mean'"),
    (["q1", "q1"], r"output_names must be distinct and not 'mean'"),
])
def test_evaluate_refuses_wrong_output_names(names, message):
    rng = np.random.default_rng(1)
    u, y = rng.normal(size=(100, 1)), rng.normal(size=(100, 2))
    model = LinearARX(1, 1).fit(u, y)
    with pytest.raises(ValueError, match=message):
        evaluate(model, u, y, output_names=names)


# 5. KUKA .mat orientation


def _write_kuka(path, transpose=(), shapes=None):
    rng = np.random.default_rng(0)
    data = {"u_train": rng.normal(size=(6, 1212)), "y_train": rng.normal(size=(6, 1212)),
            "u_test": rng.normal(size=(6, 606)), "y_test": rng.normal(size=(6, 606))}
    data.update({k: rng.normal(size=s) for k, s in (shapes or {}).items()})
    savemat(path, {k: (v.T if k in transpose else v) for k, v in data.items()})
    return data


def test_kuka_variables_are_read_in_either_orientation(tmp_path):
    data = _write_kuka(tmp_path / "as_documented.mat")
    _write_kuka(tmp_path / "transposed.mat", transpose=("u_train", "y_train", "u_test", "y_test"))
    _write_kuka(tmp_path / "mixed.mat", transpose=("u_train", "y_test"))
    for name in ("as_documented.mat", "transposed.mat", "mixed.mat"):
        r = load_kuka(tmp_path / name)
        assert [a.shape for a in r.u_train] == [(606, 6), (606, 6)], name
        assert [a.shape for a in r.y_test] == [(606, 6)], name
        np.testing.assert_array_equal(np.vstack(r.u_train), data["u_train"].T)
        np.testing.assert_array_equal(np.vstack(r.y_test), data["y_test"].T)


@pytest.mark.parametrize("shape", [(5, 606), (606, 7)])
def test_kuka_variable_without_six_channels_is_refused(tmp_path, shape):
    _write_kuka(tmp_path / "bad.mat", shapes={"y_test": shape})
    with pytest.raises(ValueError, match=rf"bad\.mat: variable 'y_test' has shape \({shape[0]}, "
                                         rf"{shape[1]}\); expected 6 channels"):
        load_kuka(tmp_path / "bad.mat")


# 6. magnitudes that break float64 numerics


@pytest.mark.parametrize(("scale", "message"), [
    (1e-160, r"y channel 1 has no value above 1e-150 in magnitude \(largest 4e-159\)"),
    (1e300, r"y channel 1 reaches magnitude 4e\+301, above 1e\+150"),
])
def test_signals_too_small_or_too_large_for_float64_are_refused(scale, message):
    u, y = _arx_data()
    y2 = np.column_stack([y, y * scale])
    y2[5, 1] = 40 * scale
    with pytest.raises(ValueError, match=message + r".*rescale the data \(e\.g\. to engineering units\)"):
        LinearARX(1, 1).fit(u, y2)


def test_all_zero_channel_and_moderate_scales_are_accepted():
    u, y = _arx_data()
    for scale in (1e-140, 1e140):
        as_experiments(u * scale, np.column_stack([y * scale, np.zeros(len(y))]))


# users' tables: what used to be read silently wrong or fail late, refused naming the file


def _write(tmp_path, name: str, frame: pd.DataFrame):
    path = tmp_path / name
    frame.to_parquet(path) if name.endswith(".parquet") else frame.to_csv(path, index=False)
    return path


def test_a_column_named_twice_in_the_header_is_refused(tmp_path):
    path = tmp_path / "d.csv"
    path.write_text("u1,u1,y1\n1,2,3\n4,5,6\n")
    with pytest.raises(ValueError, match=r"d\.csv names column\(s\) \['u1'\] more than once"):
        load_table(path, ["u1"], ["y1"])


def test_a_date_time_column_given_as_an_input_is_refused(tmp_path):
    frame = pd.DataFrame({"t": pd.date_range("2026-01-01", periods=30, freq="s"),
                          "y1": np.arange(30.0)})
    path = _write(tmp_path, "d.parquet", frame)
    with pytest.raises(ValueError, match=r"d\.parquet: column 't' holds datetime64\[.s\] "
                                         r"values, not numbers.*--time"):
        load_table(path, ["t"], ["y1"])


def test_a_constant_output_column_is_refused(tmp_path):
    path = _write(tmp_path, "d.csv", pd.DataFrame({"u1": np.arange(30.0), "y1": 3.0,
                                                   "y2": np.arange(30.0)}))
    with pytest.raises(ValueError, match=r"d\.csv: output column\(s\) \['y1'\] hold one value "
                                         r"in every row \(e\.g\. 3\)"):
        load_table(path, ["u1"], ["y1", "y2"])


def test_values_whose_squares_overflow_are_refused_at_once(tmp_path):
    y = np.arange(30.0)
    y[7] = 1e200
    path = _write(tmp_path, "d.csv", pd.DataFrame({"u1": np.arange(30.0), "y1": y}))
    with pytest.raises(ValueError, match=r"d\.csv: column 'y1' has 1 value\(s\) beyond "
                                         r"±1e\+150 \(first: 1e\+200 at row 7\)"):
        load_table(path, ["u1"], ["y1"])


@pytest.mark.parametrize("name", ["d.csv", "d.parquet"])
def test_a_table_without_rows_is_refused(tmp_path, name):
    path = _write(tmp_path, name, pd.DataFrame({"u1": pd.Series(dtype=float),
                                                "y1": pd.Series(dtype=float)}))
    with pytest.raises(ValueError, match=r"has a header but no data rows"):
        load_table(path, ["u1"], ["y1"])


@pytest.mark.parametrize(("name", "content"), [("d.csv", b""), ("d.csv", b"\xff\xfe\x00\x81"),
                                               ("d.parquet", b"not parquet")])
def test_an_empty_or_binary_file_is_refused_naming_it(tmp_path, name, content):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(ValueError, match=rf"{path} cannot be read as a "
                                         rf"{name.split('.')[1]} table"):
        load_table(path, ["u1"], ["y1"])


# signals and warm-ups that used to give a silently wrong result or a late memory error


@pytest.mark.parametrize("n_init", [5000, 200, -1, 2.5, True])
@pytest.mark.parametrize("model", [LinearARX(na=1, nb=1), SubspaceSS(order=1, horizon=3)])
def test_a_warm_up_outside_the_samples_is_refused(n_init, model):
    u, y = _arx_data(200)
    model.fit(u, y)
    with pytest.raises(ValueError, match=r"n_init (= .* must be at least 0 and below the 200 "
                                         r"samples given|must be a whole number)"):
        model.predict(u, y, n_init=n_init)
    assert model.predict(u, y, n_init=199).shape == (200, 1)  # the last one is predicted


def test_text_is_refused_rather_than_converted():
    u, y = _arx_data(50)
    with pytest.raises(ValueError, match=r"u must be numeric: it holds text \(dtype <U"):
        as_signal(u.astype(str), "u")
    with pytest.raises(ValueError, match=r"y must be numeric: it holds text \(dtype object\)"):
        as_signal(np.array([["1.0"], [2.0]], dtype=object), "y")


def test_transposed_signals_are_refused_with_a_shape_error():
    rng = np.random.default_rng(0)
    u, y = rng.normal(size=(2, 4000)), rng.normal(size=(2, 4000))  # (channels, samples)
    with pytest.raises(ValueError, match=r"u has shape \(2, 4000\): 4000 channels of 2 "
                                         r"sample\(s\).*transposed"):
        LinearARX(na=1, nb=1).fit(u, y)


@pytest.mark.parametrize("make", [lambda: PWARX(na=1, nb=1), lambda: LinearARX(na=1, nb=1),
                                  lambda: SubspaceSS(order=1, horizon=3)],
                         ids=["PWARX", "LinearARX", "SubspaceSS"])
@pytest.mark.parametrize(("u", "y", "message"), [
    (np.empty((0, 2)), np.empty((0, 1)), r"u and y have no samples \(shapes \(0, 2\) and "
                                         r"\(0, 1\)\): an experiment needs at least one"),
    ([], [], r"u and y have no samples"),
    ([np.ones((50, 1)), np.empty((0, 1))], [np.ones((50, 1)), np.empty((0, 1))],
     r"u and y \(experiment 1\) have no samples"),
])
def test_empty_signals_are_refused_naming_them(make, u, y, message):
    """Not numpy's "zero-size array to reduction operation minimum"."""
    with pytest.raises(ValueError, match=message):
        make().fit(u, y)


def test_min_pts_above_the_local_models_is_said_so_not_taken_for_memory():
    """MinPts larger than the local models to cluster is that, not a memory request of
    thousands of GiB."""
    rng = np.random.default_rng(0)
    u = rng.normal(size=(400, 1))
    y = np.zeros((400, 1))
    for k in range(1, 400):
        y[k] = 0.5 * y[k - 1] + u[k - 1] - 0.3 * np.sign(y[k - 1])
    for min_pts in (10**9, 1000):
        model = PWARX(na=1, nb=1).set_params(clustering__min_pts=min_pts)
        with pytest.raises(ValueError, match=rf"clustering min_pts = {min_pts} is larger than "
                                             r"the 399 local models there are to cluster"):
            model.fit(u, y)


@pytest.mark.parametrize("lengths", [(400, 400, 1), (400, 400, 12), (1, 400, 400, 1)])
def test_a_held_out_experiment_too_short_for_the_search_is_named(lengths):
    """A held-out experiment too short to score a free run is named with the samples it
    needs, not reported as "every linear candidate diverges"."""
    rng = np.random.default_rng(0)
    n = sum(lengths)
    u = rng.normal(size=(n, 1))
    y = np.zeros((n, 1))
    for k in range(1, n):
        y[k] = 0.5 * y[k - 1] + u[k - 1] - 0.3 * np.sign(y[k - 1])
    cuts = np.cumsum(lengths)[:-1]
    short = len(lengths) - 1
    with pytest.raises(ValueError, match=rf"held-out experiment {short} has {lengths[-1]} "
                                         rf"sample\(s\): the structure search scores the free "
                                         rf"run of each held-out experiment after a warm-up of "
                                         rf"10 samples and needs at least 30"):
        PWARX.auto(na=1, nb=1, max_candidates=5).fit(np.split(u, cuts), np.split(y, cuts))
