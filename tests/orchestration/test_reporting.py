"""The tables of the asset pages."""

import numpy as np

from pwa_pipeline.orchestration.reporting import regions_table
from pwa_pipeline.pwa import SVMRegions
from pwa_pipeline.pwa.partitions import SignRegions


def test_the_regions_table_shows_an_svms_rows_and_any_other_maps_inequalities():
    rng = np.random.default_rng(0)
    phi = np.column_stack([rng.normal(size=200), np.ones(200)])
    svm = SVMRegions().fit(phi, (phi[:, 0] > 0).astype(int))
    table = regions_table(svm, ["y1(k-1)", "1"])
    assert list(table.index) == ["H1", "H2"] and list(table.columns) == ["y1(k-1)", "1", "b"]
    np.testing.assert_array_equal(table[["y1(k-1)", "1"]].to_numpy(), svm.coef_)
    # a map without score rows (here the signs of φ1 − φ2): its halfspaces, row by row
    table = regions_table(SignRegions(np.array([[1.0, -1.0]])), ["a", "b"])
    assert list(table.index) == ["H1.1", "H2.1"] and list(table.columns) == ["a", "b", "≤ q"]
    np.testing.assert_array_equal(table.to_numpy(), [[1.0, -1.0, 0.0], [-1.0, 1.0, 0.0]])
