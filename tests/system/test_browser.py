"""Both UIs in a real browser: ``dagster dev`` and ``mlflow ui`` on a temporary store, driven
by pip's playwright on Debian's chromium, as a user would use them (README, *The UIs*).

The servers start once for the module (about 20 s) and are ended, process group and all, at
its end, also on a failure. One partition is launched from *Jobs → sweep*; the tests read what
its run left in both UIs, and the last ones run the same partition again from the command
line. A screenshot of every test's last page goes to the directory printed at the start
(``$PWA_SCREENSHOTS`` to choose it). Without chromium these tests skip, saying how to install
it; CI installs it (``.ci/run``) and makes such a skip a failure.
"""

import os
import re
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

import pytest

from benchmarks._ui import (
    LAPTOP,
    LOCATION,
    VIEWPORT,
    chart_numbers,
    collapse_chart_sections,
    compare_all_runs,
    dismiss_mlflow_popups,
    duration_seconds,
    image_state,
    launch_from_sweep,
    mlflow_experiment_id,
    mlflow_popups,
    mlflow_run_page,
    mlflow_runs_url,
    open_asset_graph,
    open_figure,
    open_in_app,
    search_charts,
    significant_digits,
    ui_stack,
    watch_live_run,
)
from pwa_pipeline.methods import METHODS
from pwa_pipeline.orchestration.jobs import LEADERBOARD_JOB, LEADERBOARD_SENSOR, SWEEP_JOB
from pwa_pipeline.orchestration.paths import MLFLOW_TRAINING_VIEW
from pwa_pipeline.orchestration.reporting import MODEL, PER_OUTPUT

pytestmark = [pytest.mark.browser, pytest.mark.xdist_group("browser")]

DATASET, HPARAMS = "hure_vasak", "paper"  # the cheapest partition: seconds of compute
PARTITION = f"{DATASET}|{HPARAMS}"
#: The PWA chain's step assets, in the paper's order.
CHAIN = ["regressors", "local_models", "clusters", "sub_models", "svm_regions",
         "output_error_refinement", "pwa_model"]
#: A run's headline metrics in MLflow (unprefixed), and what a diverged free run logs instead
#: of its NRMSE.
HEADLINE = {"one_step_nrmse", "one_step_r2", "free_run_nrmse", "free_run_r2",
            "free_run_diverged", "fit_seconds"}
DIVERGED = {"free_run_divergence_experiment", "free_run_divergence_sample",
            "free_run_nrmse_before_divergence"}
#: At most this many unprefixed metrics per run (the headline ones and a few more, such as
#: the shares outside the data envelope), so that the chart view opens on a few charts.
FEW = 8
#: A reST role (``:mod:`x```), rendered or not.
REST_ROLE = re.compile(r"(?<![\w:]):[a-z]+(?::[a-z]+)?:(?=[`\w.~])")


def _defs():
    from pwa_pipeline.definitions import defs

    return defs


def _tags(run: dict) -> dict:
    return {t["key"]: t["value"] for t in run["tags"]}


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


@contextmanager
def _page(browser, viewport: dict, screenshot: Path):
    """A page in a fresh browser context (a first visit: no stored UI choices), its last
    state photographed on the way out."""
    context = browser.new_context(viewport=viewport)
    page = context.new_page()
    page.set_default_timeout(30_000)
    try:
        yield page
    finally:
        page.screenshot(path=screenshot)
        context.close()


@pytest.fixture
def page(browser, shots, request):
    with _page(browser, VIEWPORT, shots / f"{request.node.name}.png") as page:
        yield page


@pytest.fixture
def laptop(browser, shots, request):
    """A page on a laptop's screen (:data:`benchmarks._ui.LAPTOP`)."""
    with _page(browser, LAPTOP, shots / f"{request.node.name}.png") as page:
        yield page


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


# ------------------------------------------------------------------------------------ Dagster

def test_the_asset_graph_lists_every_asset_in_its_group(page, stack):
    defs = _defs()
    graph = defs.resolve_asset_graph()
    names = sorted(key.to_user_string() for key in graph.get_all_asset_keys())
    groups = {graph.get(key).group_name for key in graph.get_all_asset_keys()}
    assert groups == {"data", "identification", "models", "scores", "comparison"}
    boxes = open_asset_graph(page, stack, len(names))  # as the docs advise: side by side,
    # the whole graph fits only at a zoom where Dagster draws no node
    labels = sorted(boxes)
    # a long name is shortened in the middle at this zoom: output…_refinement
    assert sorted(name for name in names for label in labels if _shows(label, name)) == names
    assert len(labels) == len(names)
    shown = page.locator("foreignObject:not([style])").evaluate_all(
        "nodes => nodes.map(n => n.textContent).filter(t => t)")  # the groups' titles
    assert set(shown) == groups


def _shows(label: str, name: str) -> bool:
    head, dots, tail = label.partition("…")
    return label == name or bool(dots) and name.startswith(head) and name.endswith(tail) \
        and len(head) + len(tail) < len(name)


def test_the_asset_graph_reads_the_chain_top_to_bottom(page, stack):
    """Top to bottom, every group expanded: the chain's steps one below the other in one
    column, each drawn depending on the step before it alone (no edge from elsewhere into
    the chain after its first step)."""
    graph = _defs().resolve_asset_graph()
    for before, step in zip(CHAIN, CHAIN[1:], strict=False):
        parents = {key.to_user_string() for key in graph.get(_key(step)).parent_keys}
        assert parents == {before}, (step, parents)
    assert {graph.get(_key(step)).group_name for step in CHAIN[:-1]} == {"identification"}
    boxes = open_asset_graph(page, stack, len(graph.get_all_asset_keys()))
    chain = [next(box for label, box in boxes.items() if _shows(label, step)) for step in CHAIN]
    tops = [box["y"] for box in chain]
    centres = [box["x"] + box["width"] / 2 for box in chain]
    assert tops == sorted(tops) and len(set(tops)) == len(tops), tops
    assert max(centres) - min(centres) < 2, centres  # one column


def _key(name: str):
    import dagster as dg

    return dg.AssetKey(name)


def test_the_run_page_follows_the_run_live(launched):
    """While the run goes, its page lists the step in flight (an asset's op, or ``pwa_fit``,
    the op of the chain's assets); when it ends, the page says so without a reload, and lists
    nothing as executing."""
    run, text, executing = launched
    steps = set(_defs().resolve_job_def(SWEEP_JOB).graph.node_names())
    assert "pwa_fit" in steps and not set(CHAIN) & steps
    assert executing and executing <= steps, executing
    assert "Executing (0)" in text and "Success" in text


def test_a_partition_launched_from_the_sweep_job_succeeds(launched):
    run, text, _ = launched
    tags = _tags(run)
    assert (run["status"], run["jobName"], tags["dagster/partition"]) == (
        "SUCCESS", SWEEP_JOB, PARTITION)
    assert {s["status"] for s in run["stepStats"]} == {"SUCCESS"}
    steps = _defs().resolve_job_def(SWEEP_JOB).graph.node_names()
    assert sorted(s["stepKey"] for s in run["stepStats"]) == sorted(steps)  # every asset's op
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
    ("clusters", "local models by cluster"),
    ("pwa_model", "switching (first held-out experiment)"),
    ("pwa_model", "regions"),
    *[(f"{method}_scores", "prediction") for method in METHODS],
])
def test_an_asset_page_shows_its_figure_on_a_laptop_screen(laptop, stack, launched, asset,
                                                           key):
    """Every figure an asset page promises is there, decoded, drawn to its bottom, and shown
    whole on a 1366×768 screen without scrolling inside its dialog."""
    image = open_figure(laptop, stack, asset, key)
    assert image.get_attribute("src").startswith("data:image/png;base64,")
    decoded, width, height, drawn_to_the_bottom = image_state(image)
    assert decoded and width > 400 and height > 200 and drawn_to_the_bottom
    assert image.is_visible()
    box = image.bounding_box()
    assert box["height"] <= LAPTOP["height"], f"{asset} {key!r}: {box} (natural {width}×{height})"
    assert box["y"] >= 0 and box["y"] + box["height"] <= LAPTOP["height"], \
        f"{asset} {key!r} not wholly on screen: {box} (natural {width}×{height})"
    scrolls = image.evaluate("""i => { const out = [];
        for (let e = i.parentElement; e; e = e.parentElement) {
            const y = getComputedStyle(e).overflowY;
            if ((y === "auto" || y === "scroll") && e.scrollHeight > e.clientHeight + 1)
                out.push([e.tagName, e.scrollHeight, e.clientHeight]); }
        return out; }""")
    assert not scrolls, f"{asset} {key!r}: the figure's dialog scrolls: {scrolls}"


def test_asset_descriptions_are_plain_markdown(page, stack, launched):
    """No description shows a reST role (``:mod:`x```) or a stray backtick once rendered on
    its asset page, nor a role in the catalog, which shows their beginning unrendered."""
    graph = _defs().resolve_asset_graph()
    described = {key.to_user_string(): graph.get(key).description
                 for key in graph.get_all_asset_keys()}
    assert all(described.values()), [name for name, text in described.items() if not text]
    page.goto(f"{stack.dagster_url}/assets")
    page.get_by_text(_opening(described["clusters"])).first.wait_for()
    raw = page.inner_text("body")
    assert not REST_ROLE.findall(raw), REST_ROLE.findall(raw)
    shown = {}
    for name, text in described.items():
        open_in_app(page, f"/assets/{name}")
        opening = page.get_by_text(_opening(text)).first
        opening.wait_for()
        shown[name] = opening.evaluate("e => e.closest('div').innerText")
    roles = {name: REST_ROLE.findall(text) for name, text in shown.items()
             if REST_ROLE.search(text)}
    assert not roles, roles
    backticks = {name: text for name, text in shown.items() if "`" in text}
    assert not backticks, backticks


def _opening(description: str) -> str:
    """Words from the beginning of a description that no Markdown markup touches."""
    plain = (part.strip() for part in re.split(r"[`*_\[\]()\\]", description))
    return next(part for part in plain if len(part) >= 12)[:30].strip()


# ------------------------------------------------------------------------------------- MLflow

def test_the_mlflow_run_page_shows_its_headline_metrics_description_and_duration(
        page, stack, launched):
    """The PWA run's page, opened from the link on ``pwa_scores``: its description says what
    the model is; its metrics are the headline ones and prefixed others, none shown with
    more than 4 significant digits; its duration spans the fit."""
    from mlflow.tracking import MlflowClient

    page.goto(f"{stack.dagster_url}/assets/pwa_scores")
    link = page.locator("tr", has=page.get_by_text("mlflow_run", exact=True)).locator("a").first
    experiment = mlflow_experiment_id(stack, DATASET)
    href = link.get_attribute("href")
    assert href.startswith(f"{stack.mlflow_url}/#/experiments/{experiment}/runs/")
    assert href.endswith(MLFLOW_TRAINING_VIEW)
    page.goto(href)  # the run's page, in the model-training view (its sidebar has the registry)
    page.get_by_role("heading", name=f"pwa|{HPARAMS}").wait_for()
    page.get_by_role("link", name="Model registry").wait_for()
    dismiss_mlflow_popups(page)
    shown = mlflow_run_page(page)
    assert shown["description"].startswith(
        f"The pwa model of data set {DATASET}, hyper-parameter set {HPARAMS}."), shown
    metrics = shown["metrics"]
    headline = {name for name in metrics if "/" not in name}
    if metrics["free_run_diverged"] == "1":  # no free-run score, but where it diverged
        assert not {"free_run_nrmse", "free_run_r2"} & headline, headline
        assert HEADLINE - {"free_run_nrmse", "free_run_r2"} <= headline, headline
        assert {"free_run_divergence_experiment", "free_run_divergence_sample"} <= headline
    else:
        assert HEADLINE <= headline and not DIVERGED & headline, headline
    assert len(headline) <= FEW, headline
    # the model's facts are params, never charts; the run has a colour of its method's
    assert {name.split("/")[0] + "/" for name in metrics if "/" in name} == {PER_OUTPUT}
    assert f"{PER_OUTPUT}free_run_nrmse_y1" in metrics
    long = {name: value for name, value in metrics.items() if significant_digits(value) > 4}
    assert not long, long
    fit = float(metrics["fit_seconds"])
    run = MlflowClient(stack.tracking_uri).get_run(href.split("/runs/")[1].split("?")[0])
    assert f"{MODEL}n_submodels" in run.data.params and not any(
        name.startswith(MODEL) for name in run.data.metrics)
    assert run.data.tags["mlflow.runColor"] == METHODS["pwa"].colour
    assert (run.info.end_time - run.info.start_time) / 1000 >= fit, (run.info, fit)
    if fit >= 1:  # as shown: 6.9s, never 244ms
        assert not shown["duration"].endswith("ms"), shown["duration"]
        assert duration_seconds(shown["duration"]) >= round(fit, 1) - 0.05, (shown, fit)
    assert not mlflow_popups(page)


def test_the_mlflow_chart_view_shows_the_headline_metrics_to_scale(page, stack, launched):
    """The experiment's chart view: a section for the per-output metrics (the model's facts
    are params, drawn as no chart) and one of few unprefixed ones; once the first is folded,
    the headline charts (searched for,
    as the view draws only charts in view): a chart for every headline metric, each score's
    axis spanning the scores' own range (no capped NRMSE of 10, R² of −99 or 1e30 stretching
    it), its labels short."""
    experiment = mlflow_experiment_id(stack, DATASET)
    page.goto(mlflow_runs_url(stack, experiment, f"tags.hparams = '{HPARAMS}'", charts=True))
    page.get_by_text("Model metrics").first.wait_for()
    dismiss_mlflow_popups(page)
    sections = re.findall(r"^(.+)\n\((\d+)\)$", page.inner_text("body"), re.MULTILINE)
    assert {name for name, _ in sections} == {"per_output", "Model metrics",
                                              "System metrics"}, sections
    assert 0 < int(dict(sections)["Model metrics"]) <= FEW, sections  # the unprefixed ones
    collapse_chart_sections(page, PER_OUTPUT.rstrip("/"))
    page.get_by_text("fit_seconds", exact=True).first.wait_for()  # the first headline chart
    search_charts(page, f"^({'|'.join(sorted(HEADLINE))})$")  # the rest drawn once in view
    drawn = {title: chart_numbers(page, title) for title in sorted(HEADLINE)}
    for title in ("one_step_nrmse", "one_step_r2", "free_run_nrmse", "free_run_r2"):
        values = [float(v) for v in drawn[title]]
        assert len(values) > len(METHODS) and -1 <= min(values) and max(values) <= 2, \
            (title, drawn[title])
    long = {title: v for title, values in drawn.items() for v in values
            if significant_digits(v) > 4}
    assert not long, long
    page.evaluate("window.scrollTo(0, 0)")
    assert not mlflow_popups(page)


def test_the_mlflow_runs_view_lists_every_method_and_compares_them(page, stack, launched):
    experiment = mlflow_experiment_id(stack, DATASET)
    runs = [f"{method}|{HPARAMS}" for method in METHODS]
    assert sorted(runs) == [f"{m}|{HPARAMS}" for m in ("linear_arx", "pwa", "subspace")]
    # the set's runs (the leaderboard's run in the same experiment left out)
    page.goto(mlflow_runs_url(stack, experiment, f"tags.hparams = '{HPARAMS}'"))
    for name in runs:
        page.get_by_role("link", name=name, exact=True).wait_for()
    dismiss_mlflow_popups(page)
    compare_all_runs(page)
    page.get_by_text("Comparing 3 Runs").wait_for()
    for name in runs:
        assert page.get_by_text(name, exact=True).count()
    dismiss_mlflow_popups(page, settle_ms=300)
    assert not mlflow_popups(page)


def test_the_registered_models_appear_in_the_registry(page, stack, launched):
    page.goto(f"{stack.mlflow_url}/#/models")
    for method in METHODS:
        page.get_by_role("link", name=f"pwa-pipeline.{DATASET}.{method}", exact=True).wait_for()
    dismiss_mlflow_popups(page)  # the registry's announcement, the assistant
    assert not mlflow_popups(page)


def test_a_registered_model_version_says_where_it_came_from(page, stack, launched):
    """Each method's model version 1: tagged with its data set, set, method, partition and
    both runs (the MLflow run that logged it, the Dagster run), and described."""
    from mlflow.tracking import MlflowClient

    run, _, _ = launched
    client = MlflowClient(stack.tracking_uri)
    experiment = mlflow_experiment_id(stack, DATASET)
    for method in METHODS:
        (logged,) = client.search_runs([experiment], filter_string=(
            f"tags.method = '{method}' and tags.hparams = '{HPARAMS}'"))
        page.goto(f"{stack.mlflow_url}/#/models/pwa-pipeline.{DATASET}.{method}/versions/1")
        page.get_by_role("cell", name="dagster_run_id", exact=True).wait_for()
        dismiss_mlflow_popups(page, settle_ms=500)
        tags = {key: page.locator("tr", has=page.get_by_role("cell", name=key, exact=True))
                .first.inner_text().split(maxsplit=1)[1].strip()
                for key in ("dataset", "hparams", "method", "partition", "mlflow_run_id",
                            "dagster_run_id")}
        assert tags == {"dataset": DATASET, "hparams": HPARAMS, "method": method,
                        "partition": PARTITION, "mlflow_run_id": logged.info.run_id,
                        "dagster_run_id": run["runId"]}, (method, tags)
        page.get_by_text(f"The {method} model of data set {DATASET}, hyper-parameter set "
                         f"{HPARAMS}.").first.wait_for()
        page.get_by_role("link", name=f"{method}|{HPARAMS}", exact=True).wait_for()  # its run
        assert not mlflow_popups(page)


# ------------------------------------------------------------------- the leaderboard's sensor

def test_the_leaderboard_is_refreshed_after_the_sweep_run(page, stack, launched):
    """The ``leaderboard_refresh`` sensor (on by default, evaluated every 30 s by the daemon
    of ``dagster dev``) materialises the leaderboard after the UI's sweep run ended; its page
    shows that materialisation, not stale, and its MLflow run's metrics short."""
    run, _, _ = launched
    deadline = time.monotonic() + 150
    while True:
        board = stack.asset("leaderboard")
        refreshed = [m for m in board["assetMaterializations"]
                     if int(m["timestamp"]) / 1000 > run["endTime"]
                     and _tags(stack.run(m["runId"])).get("dagster/sensor_name") ==
                     LEADERBOARD_SENSOR]
        if refreshed or time.monotonic() > deadline:
            break
        time.sleep(2)
    assert refreshed, f"no refresh by {LEADERBOARD_SENSOR} within 150 s of the run's end: {board}"
    assert board["staleStatus"] == "FRESH", board
    latest = board["assetMaterializations"][0]["runId"]
    page.goto(f"{stack.dagster_url}/assets/leaderboard")
    page.locator(f"a[href*='/runs/{latest}']").first.wait_for()  # its latest materialisation
    text = page.inner_text("body")
    assert "Unsynced" not in text and "Stale" not in text
    link = page.locator("tr", has=page.get_by_text(f"mlflow_run {DATASET}", exact=True)) \
        .locator("a").first
    page.goto(link.get_attribute("href"))
    page.get_by_role("heading", name="leaderboard", exact=True).wait_for()
    dismiss_mlflow_popups(page)
    metrics = mlflow_run_page(page)["metrics"]
    long = {name: value for name, value in metrics.items() if significant_digits(value) > 4}
    assert metrics and not long, long


# ---------------------------------------------------- what the first visit and the CLI lead to

@pytest.fixture(scope="module")
def from_the_command_line(stack, launched):
    """``python -m pwa_pipeline run --partition hure_vasak|paper`` on the UI's stores, after
    everything above read them: its completed process and the Dagster runs it made."""
    before = {r["runId"] for r in stack.runs()}
    done = stack.cli("run", "--partition", PARTITION)
    made = [r for r in stack.runs() if r["runId"] not in before
            and LEADERBOARD_SENSOR != _tags(r).get("dagster/sensor_name")]
    return done, made


def test_runs_from_the_command_line_are_listed_on_their_jobs_pages(page, stack, launched,
                                                                   from_the_command_line):
    """The command line's partition is a run of ``sweep`` and its leaderboard one of
    ``refresh_leaderboard``, each listed on its job's *Runs* tab like a run launched there."""
    done, made = from_the_command_line
    assert done.returncode == 0, done.stdout[-3000:]
    jobs = sorted(r["jobName"] for r in made)
    assert jobs == sorted([SWEEP_JOB, LEADERBOARD_JOB]), made
    (sweep,) = (r for r in made if r["jobName"] == SWEEP_JOB)
    assert (sweep["status"], _tags(sweep).get("dagster/partition")) == ("SUCCESS", PARTITION)
    ui_run = launched[0]["runId"]
    for job in (SWEEP_JOB, LEADERBOARD_JOB):
        (cli_run,) = (r["runId"] for r in made if r["jobName"] == job)
        page.goto(f"{stack.dagster_url}/locations/{LOCATION}/jobs/{job}/runs")
        page.get_by_text(f"job:{job}").first.wait_for()
        if job == SWEEP_JOB:
            page.get_by_text(ui_run[:8], exact=True).first.wait_for()  # the list is in
        else:
            page.wait_for_timeout(2000)
        listed = page.get_by_text(cli_run[:8], exact=True).count()
        assert listed, f"{job}'s Runs tab does not list the command line's run {cli_run}"


def test_the_mlflow_link_the_command_line_prints_opens_the_training_runs(
        page, stack, launched, from_the_command_line):
    """The command line ends with a link per data set to its experiment's runs in the
    model-training view; in a browser that never used MLflow it opens those runs, not the
    GenAI overview (which MLflow 3.17's experiment list opens whatever the experiment's
    kind), with no pop-up in the way; the experiment is tagged as model development."""
    from mlflow.tracking import MlflowClient

    done, _ = from_the_command_line
    experiment = mlflow_experiment_id(stack, DATASET)
    tags = MlflowClient(stack.tracking_uri).get_experiment(experiment).tags
    assert tags.get("mlflow.experimentKind") == "custom_model_development", tags
    link = f"{stack.mlflow_url}/#/experiments/{experiment}/runs{MLFLOW_TRAINING_VIEW}"
    assert f"     {DATASET}: {link}\n" in done.stdout, done.stdout[-1500:]
    page.goto(link)
    page.get_by_role("link", name=f"pwa|{HPARAMS}", exact=True).first.wait_for()
    dismiss_mlflow_popups(page)
    assert f"/experiments/{experiment}/runs" in page.url, f"opened {page.url}"
    assert not mlflow_popups(page)
