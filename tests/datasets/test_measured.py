"""The measured benchmarks' loaders (cascaded tanks, EMPS): official splits and conventions
from the real files where present, clear errors on missing or malformed files, and the
benchmark's own figure of merit."""

import numpy as np
import pandas as pd
import pytest
from scipy.io import savemat

from pwa_pipeline.datasets import EMPS, TANKS, Dataset, load_cascaded_tanks, load_emps
from pwa_pipeline.datasets.measured import EMPS_CONVENTION, TANKS_CONVENTION
from pwa_pipeline.orchestration.run_records import benchmark_metric
from pwa_pipeline.scoring.conventions import single_run_scores


def _tanks_csv(folder, n=1024, drop=None):
    rng = np.random.default_rng(0)
    table = pd.DataFrame({"uEst": rng.uniform(0, 6, n), "uVal": rng.uniform(0, 6, n),
                          "yEst": rng.uniform(3, 10, n), "yVal": rng.uniform(2, 10, n),
                          "Ts": [4.0] + [np.nan] * (n - 1)})
    table.drop(columns=drop or []).to_csv(folder / "dataBenchmark.csv", index=False)
    return table


def _emps_mats(folder, n=500, drop=None):
    t = np.arange(n) * 1e-3
    for i, file in enumerate(EMPS.files):
        record = {"t": t[:, None], "vir": np.sin(t + i)[:, None], "qm": np.cos(t + i)[:, None]}
        if drop:
            record.pop(drop)
        savemat(folder / file, record)


def test_missing_files_name_the_path_the_download_and_the_variable(tmp_path, monkeypatch):
    monkeypatch.setenv("PWA_TANKS_DATA", str(tmp_path))
    with pytest.raises(FileNotFoundError, match=r"dataBenchmark\.csv missing\. Download "
                                                r"CascadedTanksFiles\.zip from "
                                                r"nonlinearbenchmark\.org.*set PWA_TANKS_DATA"):
        load_cascaded_tanks()
    with pytest.raises(FileNotFoundError, match=r"DATA_EMPS\.mat.*DATA_EMPS_PULSES\.mat "
                                                r"missing\. Download EMPS\.zip.*PWA_EMPS_DATA"):
        load_emps(tmp_path)


def test_the_tanks_file_is_read_from_the_environment_variable(tmp_path, monkeypatch):
    table = _tanks_csv(tmp_path)
    monkeypatch.setenv("PWA_TANKS_DATA", str(tmp_path))
    assert TANKS.path() == tmp_path and TANKS.missing() == []
    data = load_cascaded_tanks()
    assert isinstance(data, Dataset) and data.name == "cascaded_tanks"
    np.testing.assert_array_equal(data.u_train[0][:, 0], table["uEst"])
    np.testing.assert_array_equal(data.y_test[0][:, 0], table["yVal"])
    assert (data.sample_time, data.units, data.convention) == (4.0, {"u": "V", "y": "V"},
                                                               TANKS_CONVENTION)


def test_malformed_files_name_the_file_and_the_field(tmp_path):
    _tanks_csv(tmp_path, drop=["yVal"])
    with pytest.raises(ValueError, match=r"dataBenchmark\.csv: column\(s\) \['yVal'\] missing"):
        load_cascaded_tanks(tmp_path)
    _tanks_csv(tmp_path, n=1000)
    with pytest.raises(ValueError, match=r"column 'uEst' should hold 1024 numbers, it holds "
                                         r"1000 of 1000 rows"):
        load_cascaded_tanks(tmp_path)
    _emps_mats(tmp_path, drop="qm")
    with pytest.raises(ValueError, match=r"DATA_EMPS\.mat: variable\(s\) \['qm'\] missing"):
        load_emps(tmp_path)
    (tmp_path / "DATA_EMPS.mat").write_bytes(b"\x89HDF\r\n" + bytes(200))
    with pytest.raises(ValueError, match=r"DATA_EMPS\.mat: not a MATLAB file that can be "
                                         r"read .* the benchmark's files are MATLAB v5"):
        load_emps(tmp_path)
    header = b"MATLAB 7.3 MAT-file, HDF5 schema 1.00 .".ljust(116) + bytes(8) + b"\x00\x02IM"
    (tmp_path / "DATA_EMPS.mat").write_bytes(header + bytes(512))  # saved with -v7.3
    with pytest.raises(ValueError, match=r"DATA_EMPS\.mat: a MATLAB file of a version scipy "
                                         r"does not read .*v7\.3"):
        load_emps(tmp_path)
    (tmp_path / "dataBenchmark.csv").write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(ValueError, match=r"dataBenchmark\.csv: not a CSV table that can be "
                                         r"read"):
        load_cascaded_tanks(tmp_path)
    _emps_mats(tmp_path)
    data = load_emps(tmp_path)
    assert data.u_train[0].shape == (500, 1) and data.sample_time == pytest.approx(1e-3)


def test_the_official_score_is_the_rmse_in_the_benchmarks_unit_after_its_window():
    y = np.linspace(0.0, 0.2, 100)[:, None]  # metres

    class Offset:  # a free run 2 mm off after the given samples
        def simulate(self, u, y_init):
            out = np.asarray(y, dtype=float) + 0.002
            out[: len(y_init)] = y_init
            return out

    assert single_run_scores(Offset(), np.zeros_like(y), y, EMPS_CONVENTION) == \
        pytest.approx([2.0])
    data = Dataset("emps", [y], [y], [np.zeros_like(y)], [y], ["vir"], ["qm"],
                   convention=EMPS_CONVENTION)
    assert benchmark_metric(Offset(), data) == {"benchmark/rmse_mm_from_20":
                                                pytest.approx(2.0)}
    assert benchmark_metric(Offset(), Dataset("x", [y], [y], [y], [y], ["u"], ["y"])) == {}


@pytest.mark.skipif(bool(TANKS.missing()) or bool(EMPS.missing()),
                    reason="the measured benchmarks' files are absent (PWA_TANKS_DATA, "
                           "PWA_EMPS_DATA)")
def test_the_official_files_give_the_official_splits():
    tanks, emps = load_cascaded_tanks(), load_emps()
    assert [len(x[0]) for x in (tanks.u_train, tanks.y_train, tanks.u_test, tanks.y_test)] == \
        [1024] * 4
    assert tanks.y_train[0].max() == pytest.approx(10.0)  # the sensor saturates at 10 V
    # the test output's spread after the window (the benchmark's provenance notes: 2.104 V)
    assert tanks.y_test[0][5:].std() == pytest.approx(2.104, abs=1e-3)
    assert [len(x[0]) for x in (emps.u_train, emps.u_test)] == [24841, 24841]
    assert emps.sample_time == pytest.approx(1e-3, rel=1e-4)
    assert emps.y_test[0][20:].std() * 1000 == pytest.approx(82.62, abs=0.01)
