"""Both UIs in a real browser: ``dagster dev`` and ``mlflow ui`` on a temporary store, driven
by pip's playwright on Debian's chromium, as a user would use them (README, *The UIs*).

The servers start once for the module (about 20 s) and are ended, process group and all, at
its end, also on a failure. A screenshot of every test's last page goes to the directory
printed at the start (``$PWA_SCREENSHOTS`` to choose it). Without chromium these tests skip,
saying how to install it; CI installs it (``.ci/run``) and makes such a skip a failure.
"""

import os
import tempfile
from pathlib import Path

import pytest

from benchmarks._ui import (
    VIEWPORT,
    chromium,
    compare_all_runs,
    image_state,
    launch_from_sweep,
    missing_browser,
    mlflow_experiment_id,
    mlflow_runs_url,
    open_figure,
    ui_stack,
    watch_live_run,
)
from pwa_pipeline.methods import METHODS

pytestmark = [pytest.mark.browser, pytest.mark.xdist_group("browser")]

DATASET, HPARAMS = "hure_vasak", "paper"  # the cheapest partition: seconds of compute
PARTITION = f"{DATASET}|{HPARAMS}"


@pytest.fixture(scope="module")
def browser(system_package):
    system_package("the browser tests need playwright and chromium", missing_browser())
    with chromium() as browser:
        yield browser


@pytest.fixture(scope="module")
def stack(tmp_path_factory, browser):
    with ui_stack(tmp_path_factory.mktemp("ui-store")) as stack:
        yield stack


@pytest.fixture(scope="module")
def shots():
    path = Path(os.environ.get("PWA_SCREENSHOTS") or tempfile.mkdtemp(prefix="pwa-browser-"))
    path.mkdir(parents=True, exist_ok=True)
    print(f"\nbrowser screenshots in {path}")
    return path


@pytest.fixture
def page(browser, shots, request):
    context = browser.new_context(viewport=VIEWPORT)
    page = context.new_page()
    page.set_default_timeout(30_000)
    try:
        yield page
    finally:
        page.screenshot(path=shots / f"{request.node.name}.png")
        context.close()


@pytest.fixture(scope="module")
def launched(browser, stack, shots):
    """The partition launched from *Jobs → sweep*: its finished run (API record), the text
    of its page, and the steps that page listed as executing while the run went on (the
    page watched live, never reloaded)."""
    context = browser.new_context(viewport=VIEWPORT)
    page = context.new_page()
    try:
        run_id = launch_from_sweep(page, stack, DATASET, HPARAMS)
        run, executing = watch_live_run(page, stack, run_id)
        page.get_by_text(f"partition: {PARTITION}").first.wait_for()
        page.screenshot(path=shots / "sweep_run.png")
        return run, page.inner_text("body"), executing
    finally:
        context.close()


def test_the_asset_graph_lists_every_asset(page, stack):
    from pwa_pipeline.definitions import defs

    names = sorted(key.to_user_string() for key in defs.resolve_asset_graph().get_all_asset_keys())
    assert len(names) == 16
    page.goto(f"{stack.dagster_url}/asset-groups")
    page.get_by_text("identification").first.wait_for()
    page.locator("[aria-label=settings]").last.click()  # the graph's settings
    page.get_by_role("menuitem", name="Expand all groups").click()
    page.keyboard.press("Escape")
    nodes = page.locator("foreignObject[style]")  # one per asset; groups carry a class
    page.wait_for_function("n => document.querySelectorAll('foreignObject[style]').length >= n",
                           arg=len(names))
    labels = sorted(nodes.evaluate_all("nodes => nodes.map(n => n.textContent)"))
    # a long name is shortened in the middle at this zoom: output…_refinement
    assert sorted(name for name in names for label in labels if _shows(label, name)) == names
    assert len(labels) == len(names)


def _shows(label: str, name: str) -> bool:
    head, dots, tail = label.partition("…")
    return label == name or bool(dots) and name.startswith(head) and name.endswith(tail) \
        and len(head) + len(tail) < len(name)


def test_the_run_page_follows_the_run_live(launched):
    """While the run goes, its page lists the step in flight; when it ends, the page says so
    without a reload, and lists nothing as executing."""
    from pwa_pipeline.definitions import defs

    run, text, executing = launched
    assets = {key.to_user_string() for key in defs.resolve_asset_graph().get_all_asset_keys()}
    assert executing and executing <= assets, executing
    assert "Executing (0)" in text and "Success" in text


def test_a_partition_launched_from_the_sweep_job_succeeds(launched):
    run, text, _ = launched
    tags = {t["key"]: t["value"] for t in run["tags"]}
    assert (run["status"], run["jobName"], tags["dagster/partition"]) == (
        "SUCCESS", "sweep", PARTITION)
    assert {s["status"] for s in run["stepStats"]} == {"SUCCESS"}
    assert len(run["stepStats"]) == 15  # every asset of the partition
    assert "Success" in text and PARTITION in text  # what the run's page shows


def test_the_runs_stderr_view_shows_its_captured_log(page, stack, launched):
    """The run worker's stdout and stderr, captured in Dagster's files by the command line's
    compute log manager, are what the run page's *stderr* view shows."""
    run, _, _ = launched
    (err,) = (stack.root / ".dagster_home" / "storage" / run["runId"]).rglob("*.err")
    assert "Materialized value comparison." in err.read_text()
    page.goto(f"{stack.dagster_url}/runs/{run['runId']}?logType=stderr&logFileKey={err.stem}")
    page.get_by_text("Materialized value comparison.").first.wait_for()


@pytest.mark.parametrize("asset, key", [
    ("pwa_scores", "prediction"),
    ("clusters", "local models by cluster"),
    ("pwa_model", "switching (first held-out experiment)"),
    ("pwa_model", "regions"),
])
def test_an_asset_page_shows_its_figure(page, stack, launched, asset, key):
    image = open_figure(page, stack, asset, key)
    assert image.get_attribute("src").startswith("data:image/png;base64,")
    decoded, width, height, drawn_to_the_bottom = image_state(image)
    assert decoded and width > 400 and height > 200 and drawn_to_the_bottom
    assert image.is_visible()


def test_the_mlflow_runs_view_lists_every_method_and_compares_them(page, stack, launched):
    # the run link on the scores page is the deep link into the training view
    page.goto(f"{stack.dagster_url}/assets/pwa_scores")
    link = page.locator("tr", has=page.get_by_text("mlflow_run", exact=True)).locator("a").first
    experiment = mlflow_experiment_id(stack, DATASET)
    href = link.get_attribute("href")
    assert href.startswith(f"{stack.mlflow_url}/#/experiments/{experiment}/runs/")
    page.goto(href)  # the run's page, in the model-training view (its sidebar has the registry)
    page.get_by_role("heading", name=f"pwa|{HPARAMS}").wait_for()
    page.get_by_role("link", name="Model registry").wait_for()
    page.goto(mlflow_runs_url(stack, experiment))
    runs = [f"{method}|{HPARAMS}" for method in METHODS]
    assert sorted(runs) == [f"{m}|{HPARAMS}" for m in ("linear_arx", "pwa", "subspace")]
    for name in runs:
        page.get_by_role("link", name=name, exact=True).wait_for()
    compare_all_runs(page)
    page.get_by_text("Comparing 3 Runs").wait_for()
    for name in runs:
        assert page.get_by_text(name, exact=True).count()


def test_the_registered_models_appear_in_the_registry(page, stack, launched):
    page.goto(f"{stack.mlflow_url}/#/models")
    for method in METHODS:
        page.get_by_role("link", name=f"pwa-pipeline.{DATASET}.{method}", exact=True).wait_for()
