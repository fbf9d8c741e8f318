"""What the Dagster asset pages promise and show: descriptions in plain Markdown, and every
figure a description promises on the page, for a structured set too."""

import base64
import logging
import re
import struct
from types import SimpleNamespace

import dagster as dg
import numpy as np
import pytest

from pwa_pipeline.config import HParamsFile
from pwa_pipeline.datasets import Dataset, make_hure_vasak
from pwa_pipeline.definitions import defs
from pwa_pipeline.orchestration.assets.identification import REGIONS, SWITCHING, model_output
from pwa_pipeline.orchestration.definitions import build_definitions
from pwa_pipeline.orchestration.io_manager import PartitionedFileIOManager
from pwa_pipeline.orchestration.settings import PipelineSettings
from pwa_pipeline.orchestration.tracking import MLflowTracker
from pwa_pipeline.regressors import build_regressors

#: A Sphinx role such as :mod:`x` or :func:`~x.y`, which Dagster shows raw.
ROLE = re.compile(r":[a-z]+:`")


def _descriptions(definitions) -> dict[str, str]:
    graph = definitions.resolve_asset_graph()
    return {key.to_user_string(): graph.get(key).description or ""
            for key in graph.get_all_asset_keys()}


def test_asset_descriptions_are_plain_markdown():
    descriptions = _descriptions(defs)
    assert len(descriptions) >= 15 and all(descriptions.values())
    assert {name: text for name, text in descriptions.items() if ROLE.search(text)} == {}


def _png_size(markdown: str) -> tuple[int, int]:
    png = base64.b64decode(markdown.split("base64,", 1)[1].rstrip(")"), validate=True)
    assert png.startswith(b"\x89PNG")
    return struct.unpack(">II", png[16:24])


@pytest.fixture(scope="module")
def structured_page(tmp_path_factory):
    """``pwa_model`` of a set with a structure of its own (velocity form, one model per
    output, a sign-dependent offset; as the robot's ``robot`` set) on hure_vasak, materialised with
    what it depends on: its description and its page's metadata."""
    folder = tmp_path_factory.mktemp("structured")
    path = folder / "structured.toml"
    path.write_text('[moving.hure_vasak]\nna = 1\nnb = 1\naffine = true\nform = "velocity"\n'
                    'outputs = "decoupled"\nscheduling.switch = "offset"\n')
    custom = build_definitions(path)
    resources = {"io_manager": PartitionedFileIOManager(base_dir=str(folder / "storage")),
                 "settings": PipelineSettings(cache_dir=str(folder / "cache"),
                                              hparams_path=str(path)),
                 # (the scores, which track in MLflow, are not selected)
                 "mlflow": MLflowTracker(tracking_uri=f"sqlite:///{folder / 'mlflow.db'}")}
    result = dg.materialize(list(custom.assets), partition_key="hure_vasak|moving",
                            resources=resources,
                            selection=dg.AssetSelection.assets("pwa_model").upstream())
    assert result.success
    (event,) = [e for e in result.get_asset_materialization_events()
                if e.asset_key == dg.AssetKey("pwa_model")]
    return _descriptions(custom)["pwa_model"], event.materialization.metadata, \
        result.asset_value("pwa_model")


def test_a_structured_sets_model_page_shows_what_its_description_promises(structured_page):
    """The description promises a switching and a regions entry; the page holds both for a
    model of several output groups as for the paper's route: the switching figure with a
    lane per output group and the regions of the model as eq. (1) in a slice of φ, each
    titled with data set, set and method, within a laptop screen. No reST role shows."""
    description, metadata, model = structured_page
    assert len(model.groups_) == 2 and model.structures_ == [
        "velocity (1, 1), offset (2 regions)"] * 2
    assert "*switching*" in description and "*regions*" in description
    assert not ROLE.search(description)
    switching = metadata[SWITCHING].value
    assert switching.startswith("![hure_vasak | set moving | PWA Region of each output group's "
                                "model, held-out experiment 1")
    regions = metadata[REGIONS].value
    assert regions.startswith("![hure_vasak | set moving | PWA ")
    for figure in (switching, regions):
        width, height = _png_size(figure)
        assert width <= 900 and height <= 650


def _header(table: str) -> list[str]:
    line = next(line for line in table.splitlines() if line.startswith("| output"))
    return [c.strip() for c in line.strip("|").split("|")]


def test_the_structure_table_is_narrow_with_a_column_per_candidate(tmp_path):
    """A structure chosen per output on held-out training experiments: the page lists each
    output's structure and group, and a table with one short column per candidate (its
    held-out free-run MSE), in order of richness, said in a line above it; the outputs
    carry their units; channels the data names otherwise than the model (y1…, u1…) are
    given under the model's names."""
    record = make_hure_vasak(n_samples=2400, snr_db=30, seed=0)
    test = make_hure_vasak(n_samples=600, snr_db=30, seed=1000)
    data = Dataset("hure_vasak", np.split(record.u_train[0], 4), np.split(record.y_train[0], 4),
                   [test.u_train[0]],
                   [test.y_train[0]], record.u_names, record.y_names, units={"y1": "V"})
    path = tmp_path / "h.toml"
    path.write_text('[select.hure_vasak]\nna = 1\nnb = 1\naffine = true\nform = "velocity"\n'
                    'outputs = "decoupled"\nscheduling.switch = "select"\n')
    configuration = HParamsFile(path).configuration("select", "hure_vasak")
    model = configuration.pwa.fit(data.u_train, data.y_train)
    context = SimpleNamespace(log=logging.getLogger(__name__), partition_key="hure_vasak|select")
    phi = build_regressors(list(zip(data.u_train, data.y_train, strict=True)),
                           model.output_lags_, model.nb, model.affine).phi
    output = model_output(context, PipelineSettings(cache_dir=str(tmp_path / "cache")),
                          configuration, model, data, cached=set(), phi=phi)
    structure = output.metadata["structure per output"].value
    assert _header(structure) == ["output", "structure", "group"]
    # numbered from 1, as the search's report numbers them ("experiment 4 of 4 held out")
    assert model.structure_fit_.validation_experiments == [3]
    assert output.metadata["validation_experiments"].value == "4 of 4"
    assert "regions per output group" not in output.metadata  # one output group
    # two output groups: their regions, and the modes of the model as one map
    from pwa_pipeline import PWARX
    from pwa_pipeline.pwa.scheduling import SignScheduling
    grouped = PWARX(na=1, nb=1, affine=True, form="velocity", outputs="decoupled",
                    scheduling=SignScheduling(switch="offset")).fit(data.u_train, data.y_train)
    sizes = [g.n_regions for g in grouped.groups_]
    assert sizes == [2, 2] and grouped.n_submodels_ == 4
    page = model_output(context, PipelineSettings(cache_dir=str(tmp_path / "cache3")),
                        configuration, grouped, data, cached=set(),
                        phi=build_regressors(list(zip(data.u_train, data.y_train, strict=True)),
                                             grouped.output_lags_, grouped.nb,
                                             grouped.affine).phi)
    assert page.metadata["regions per output group"].value == (
        "2, 2: the model as one PWA map (eq. 1) has their product, 4 modes (n_submodels)")
    table = output.metadata["candidates"].value
    assert table.startswith("Held-out free-run MSE of each candidate structure")
    line = next(line for line in table.splitlines() if line.startswith("|  "))
    assert [c.strip() for c in line.strip("|").split("|")] == ["", "linear", "offset", "all"]
    rows = [line for line in table.splitlines() if line.startswith("| y")]
    assert [r.split("|")[1].strip() for r in rows] == ["y1 [V]", "y2"]
    assert output.metadata[SWITCHING].value.startswith("![hure_vasak | set select | PWA ")
    assert output.metadata[REGIONS].value.startswith("![hure_vasak | set select | PWA ")
    # the data's channels named as the model names them (y1…, u1…): no key to give
    assert "names in the structures" not in output.metadata
    named = Dataset("hure_vasak", data.u_train, data.y_train, data.u_test, data.y_test,
                    ["tau1", "tau2"], ["q1", "q2"], units={"q1": "deg"})
    output = model_output(context, PipelineSettings(cache_dir=str(tmp_path / "cache2")),
                          configuration, model, named, cached=set(), phi=phi)
    assert output.metadata["names in the structures"].value == \
        "y1 = q1 [deg], y2 = q2, u1 = tau1, u2 = tau2"


def test_a_model_without_switching_says_so_on_its_page(default_30db, sim_30db):
    """One sub-model (a linear model, as a structure search that kept it): the page says
    in a line that it does not switch; a model that switches gets no such line."""
    from pwa_pipeline import LinearARX
    from pwa_pipeline.orchestration.assets.identification import switching_note

    linear = LinearARX(na=1, nb=1).fit(sim_30db.u_train, sim_30db.y_train)
    assert switching_note(linear) == "none: one mode (a single linear model)"
    assert switching_note(default_30db) is None
