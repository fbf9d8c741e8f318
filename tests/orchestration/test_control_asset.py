"""The control_model asset: a model that does not convert is said so, and never fails the
partition; one that does is written to its files."""

import dataclasses

import dagster as dg
import numpy as np

from pwa_pipeline import PWARX
from pwa_pipeline.control import PWAStateSpace
from pwa_pipeline.datasets import load_dataset
from pwa_pipeline.definitions import defs
from pwa_pipeline.orchestration.settings import PipelineSettings


def _control_asset():
    return next(a for a in defs.assets if dg.AssetKey("control_model") in a.keys)


class _Unconvertible(PWARX):
    def to_state_space(self, *args, **kwargs):
        raise NotImplementedError("regions of a step of one's own (KMeansRegions)")


def test_a_model_that_does_not_convert_is_reported_with_a_warning_check(tmp_path):
    context = dg.build_asset_context(partition_key="hure_vasak|paper")
    settings = PipelineSettings(cache_dir=str(tmp_path / "c"))
    events = list(_control_asset()(context=context, raw_benchmark=load_dataset("hure_vasak"),
                                   pwa_model=_Unconvertible(na=1, nb=1), settings=settings,
                                   configuration=settings.configuration("paper", "hure_vasak")))
    output, check = events
    assert output.value is None and output.metadata["exported"].value is False
    assert "KMeansRegions" in output.metadata["reason"].value
    assert not check.passed and check.severity == dg.AssetCheckSeverity.WARN
    assert not (tmp_path / "exports").exists()


def test_a_model_is_written_to_its_files_with_its_verdict(tmp_path):
    data = dataclasses.replace(load_dataset("hure_vasak"), sample_time=0.25)
    settings = PipelineSettings(cache_dir=str(tmp_path / "c"))
    model = settings.configuration("paper", "hure_vasak").pwa.fit(data.u_train, data.y_train)
    context = dg.build_asset_context(partition_key="hure_vasak|paper")
    output, check = _control_asset()(context=context, raw_benchmark=data, pwa_model=model,
                                     settings=settings,
                                     configuration=settings.configuration("paper", "hure_vasak"))
    ss, report = output.value.state_space, output.value.stability
    assert check.passed and ss.n_modes == model.n_submodels_ == 2
    assert output.metadata["n_modes"].value == 2
    folder = tmp_path / "exports" / "hure_vasak" / "paper"
    read = PWAStateSpace.from_json(folder / "pwa_state_space.json")
    np.testing.assert_array_equal(read.A, ss.A)
    script = (folder / "pwa_system.m").read_text()
    assert "PWASystem" in script and "Ts = 0.25;" in script  # the data's sample time
    assert output.metadata["lyapunov_certified"].value == report.certified
    assert output.metadata["max_spectral_radius"].value == float(
        f"{np.max(report.spectral_radius):.4g}")


def test_the_partition_figure_draws_each_region_where_the_model_places_it():
    """Points of the slice lie in the drawn polygon of the mode ``mode_of`` gives them."""
    from matplotlib.path import Path as PolygonPath

    from pwa_pipeline.plotting import PartitionDisplay

    data = load_dataset("hure_vasak")
    model = PipelineSettings().configuration("paper", "hure_vasak").pwa.fit(data.u_train,
                                                                          data.y_train)
    ss = model.to_state_space()
    lower, upper = ss.envelope
    fixed = (lower + upper) / 2
    fig = PartitionDisplay.from_state_space(ss, fixed, "hure_vasak | set paper | PWA").figure_
    ax = fig.axes[0]
    polygons = {int(p.get_label().split()[1]) - 1: PolygonPath(p.get_xy()) for p in ax.patches}
    assert sorted(polygons) == [0, 1]
    names = [*ss.state_names, *ss.input_names]
    i, j = names.index(ax.get_xlabel()), names.index(ax.get_ylabel())
    rng = np.random.default_rng(0)
    z = np.tile(fixed, (400, 1))
    z[:, i] = rng.uniform(lower[i], upper[i], 400)
    z[:, j] = rng.uniform(lower[j], upper[j], 400)
    modes = ss.mode_of(z[:, :ss.n_states], z[:, ss.n_states:])
    inside = {mode: poly.contains_points(z[:, [i, j]]) for mode, poly in polygons.items()}
    for mode in (0, 1):
        # (a point within a hair of a boundary may be on either side)
        assert np.mean(inside[mode] == (modes == mode)) > 0.99
    assert "hure_vasak | set paper | PWA" in fig.get_suptitle()


def test_the_partition_figure_takes_a_region_bound_on_a_coordinate_off_the_slice():
    """A region's row on a coordinate the slice fixes, the slice lying on that bound (as on
    the robot, where the structure search puts thresholds at a median and the slice fixes
    the other coordinates at theirs), is left out of qhull, not passed as a degenerate
    halfspace."""
    import copy

    from pwa_pipeline.plotting import PartitionDisplay

    data = load_dataset("hure_vasak")
    model = PipelineSettings().configuration("paper", "hure_vasak").pwa.fit(data.u_train,
                                                                          data.y_train)
    ss = copy.deepcopy(model.to_state_space())
    lower, upper = ss.envelope
    fixed = (lower + upper) / 2
    names = [*ss.state_names, *ss.input_names]
    axes = PartitionDisplay.from_state_space(ss, fixed, "").figure_.axes[0]
    shown = [names.index(axes.get_xlabel()), names.index(axes.get_ylabel())]
    off = ss.n_states  # the first input u1(k): no region of this model reads it
    unit = np.eye(len(names))
    for mode, (H, h) in enumerate(ss.regions):
        # loose bounds on the shown coordinates keep them the slice's axes
        rows, bounds = [unit[k] for k in shown * 2], [upper[k] + 1 for k in shown * 2]
        if mode == 0:  # and mode 1 bounded on u1(k), the slice on that bound itself
            rows, bounds = rows + [unit[off]], bounds + [fixed[off]]
        ss.regions[mode] = (np.vstack([H, *rows]), np.append(h, bounds))
    fig = PartitionDisplay.from_state_space(ss, fixed, "hure_vasak | set paper | PWA").figure_
    assert names[off] not in (fig.axes[0].get_xlabel(), fig.axes[0].get_ylabel())
    assert sorted(p.get_label() for p in fig.axes[0].patches) == ["mode 1", "mode 2"]
