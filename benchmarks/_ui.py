"""Both UIs on a temporary store, driven by a real browser (the browser tests and
``benchmarks/screenshots.py``).

:class:`UIStack` starts ``dagster dev`` and ``mlflow ui`` the way the README tells users to,
each in its own process group on a free loopback port, on stores under one temporary
directory (``PWA_PIPELINE_HOME``, ``DAGSTER_HOME``, a sqlite MLflow store), and ends both
groups, whatever happened. :func:`chromium` launches Debian's ``/usr/bin/chromium`` through
pip's ``playwright`` (never a browser downloaded by ``playwright install``). The page helpers
below do what a user does: launch a partition from *Jobs → sweep* (or run one from the command
line, :meth:`UIStack.cli`), open the asset graph or a figure on an asset page, close MLflow's
first-visit pop-ups, read a run's page and charts, select runs in MLflow and compare them.
"""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import quote

from pwa_pipeline.orchestration.instance import DAGSTER_YAML
from pwa_pipeline.orchestration.paths import MLFLOW_TRAINING_VIEW

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM = os.environ.get("PWA_CHROMIUM", "/usr/bin/chromium")
#: Headless, and no background traffic: without the last four, chromium keeps trying to reach
#: Google's update, sync and field-trial servers.
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                 "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync"]
INSTALL = ("install them with: python -m pip install -e '.[test]' (playwright) and "
           "apt-get install -y chromium (Debian's browser at /usr/bin/chromium; "
           "`playwright install` is not needed)")
VIEWPORT = {"width": 1280, "height": 800}
#: A laptop's screen: what a figure must fit without scrolling.
LAPTOP = {"width": 1366, "height": 768}
#: The Dagster code location of ``workspace.yaml``.
LOCATION = "pwa_pipeline"


def missing_browser() -> str | None:
    """Why the browser cannot run (with how to install it), or None."""
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return f"the Python package playwright is not installed; {INSTALL}"
    if not (Path(CHROMIUM).is_file() and os.access(CHROMIUM, os.X_OK)):
        return f"no chromium at {CHROMIUM}; {INSTALL}"
    return None


def free_port() -> int:
    """A loopback port nobody listens on now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _default_signals() -> None:
    # a shell's background job ignores SIGINT (and some runners SIGTERM too): give the servers
    # their default handlers back, so that the SIGTERM of stop() ends them at once
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_DFL)


@dataclass
class Server:
    """One server process (the leader of its own process group) and its log."""

    name: str
    url: str
    process: subprocess.Popen
    log: Path
    up_seconds: float = float("nan")

    def tail(self, lines: int = 30) -> str:
        text = self.log.read_text(errors="replace").splitlines() if self.log.exists() else []
        return "\n".join(text[-lines:])

    def terminate(self) -> None:
        """SIGTERM to the whole group (the server, its code server and run workers)."""
        _signal_group(self.process, signal.SIGTERM)

    def kill(self) -> None:
        """SIGKILL to what is left of the group, and reap the leader."""
        _signal_group(self.process, signal.SIGKILL)
        self.process.wait()


def _signal_group(process: subprocess.Popen | None, sig: int) -> None:
    if process is None:
        return
    try:
        os.killpg(process.pid, sig)
    except ProcessLookupError:  # the whole group has gone
        pass


def _get(url: str, data: bytes | None = None, timeout: float = 5.0) -> bytes:
    headers = {"Content-Type": "application/json"} if data else {}
    request = urllib.request.Request(url, data=data, headers=headers)
    with urllib.request.urlopen(request, timeout=timeout) as response:
        return response.read()


@dataclass
class UIStack:
    """``dagster dev`` and ``mlflow ui`` on fresh stores under ``root``."""

    root: Path
    servers: dict[str, Server] = field(default_factory=dict)

    @property
    def env(self) -> dict[str, str]:
        home = self.root / ".dagster_home"
        return {**os.environ,
                "PWA_PIPELINE_HOME": str(self.root), "DAGSTER_HOME": str(home),
                "MLFLOW_TRACKING_URI": self.tracking_uri,
                "PWA_DATASETS": str(self.root / "storage" / "datasets.json"),
                "PWA_MLFLOW_UI_URL": self.mlflow_url,
                "MLFLOW_DISABLE_TELEMETRY": "true", "DO_NOT_TRACK": "true",
                "DAGSTER_DISABLE_TELEMETRY": "1", "PYTHONUNBUFFERED": "1"}

    @property
    def tracking_uri(self) -> str:
        return f"sqlite:///{self.root / 'mlflow.db'}"

    @property
    def dagster_url(self) -> str:
        return self.servers["dagster"].url

    @property
    def mlflow_url(self) -> str:
        return self.servers["mlflow"].url

    def start(self, timeout: float = 240.0) -> UIStack:
        """Start both servers at once; return when Dagster has loaded the code location and
        MLflow answers ``/health`` (``up_seconds`` of each: from its start)."""
        self.root.mkdir(parents=True, exist_ok=True)
        home = self.root / ".dagster_home"
        home.mkdir(exist_ok=True)
        # what `python -m pwa_pipeline run` writes on first use (no newsletter dialog, the
        # run queue's limits); dagster dev creates the schema itself, in one process
        (home / "dagster.yaml").write_text(DAGSTER_YAML)
        ports = {"dagster": free_port(), "mlflow": free_port()}
        for name in ports:
            self.servers[name] = Server(name, f"http://127.0.0.1:{ports[name]}", None,
                                        self.root / f"{name}.log")
        commands = {
            "dagster": [sys.executable, "-m", "dagster", "dev", "-w", str(ROOT / "workspace.yaml"),
                        "-h", "127.0.0.1", "-p", str(ports["dagster"])],
            "mlflow": [sys.executable, "-m", "mlflow", "ui", "--backend-store-uri",
                       self.tracking_uri, "--host", "127.0.0.1", "--port", str(ports["mlflow"]),
                       "--workers", "1"]}
        t0 = time.perf_counter()
        try:
            for name, command in commands.items():
                server = self.servers[name]
                with open(server.log, "wb") as log:
                    server.process = subprocess.Popen(
                        command, cwd=ROOT, env=self.env, stdout=log, stderr=subprocess.STDOUT,
                        stdin=subprocess.DEVNULL, start_new_session=True,
                        preexec_fn=_default_signals)
            probes = {"dagster": self._dagster_loaded, "mlflow": self._mlflow_healthy}
            waiting = set(probes)
            while waiting:
                for name in sorted(waiting):
                    server = self.servers[name]
                    if server.process.poll() is not None:
                        raise RuntimeError(f"{name} exited with {server.process.returncode}:\n"
                                           f"{server.tail()}")
                    if probes[name](server.url):
                        server.up_seconds = time.perf_counter() - t0
                        waiting.discard(name)
                if time.perf_counter() - t0 > timeout:
                    raise TimeoutError(f"{sorted(waiting)} not up after {timeout:.0f} s:\n" +
                                       "\n".join(self.servers[n].tail() for n in waiting))
                time.sleep(0.25)
        except BaseException:
            self.stop()
            raise
        return self

    def stop(self, grace: float = 5.0) -> None:
        """End every server's process group: SIGTERM to all, SIGKILL to what is left after
        ``grace`` seconds (idempotent)."""
        started = [s for s in self.servers.values() if s.process is not None]
        for server in started:
            server.terminate()
        deadline = time.monotonic() + grace
        for server in started:
            try:
                server.process.wait(max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                pass
            server.kill()  # children that outlive their leader go too

    @staticmethod
    def _dagster_loaded(url: str) -> bool:
        query = ("{ workspaceOrError { ... on Workspace { locationEntries { name loadStatus "
                 "locationOrLoadError { __typename ... on PythonError { message } } } } } }")
        try:
            body = json.loads(_get(f"{url}/graphql", json.dumps({"query": query}).encode()))
        except OSError:
            return False
        entries = body["data"]["workspaceOrError"].get("locationEntries", [])
        for entry in entries:
            loaded = entry["locationOrLoadError"] or {}
            if entry["name"] == LOCATION and loaded.get("__typename") == "PythonError":
                raise RuntimeError(f"the code location failed to load: {loaded['message']}")
            if entry["name"] == LOCATION and entry["loadStatus"] == "LOADED" and loaded:
                return True
        return False

    @staticmethod
    def _mlflow_healthy(url: str) -> bool:
        try:
            return _get(f"{url}/health").strip() == b"OK"
        except OSError:
            return False

    def graphql(self, query: str, **variables) -> dict:
        """Dagster's GraphQL API (to read what the browser did, never to do it)."""
        body = json.loads(_get(f"{self.dagster_url}/graphql",
                               json.dumps({"query": query, "variables": variables}).encode(),
                               timeout=30))
        if body.get("errors"):
            raise RuntimeError(body["errors"])
        return body["data"]

    def run(self, run_id: str) -> dict:
        """The Dagster run: job, status, times, tags and step times."""
        query = """query($id: ID!) { runOrError(runId: $id) { __typename ... on Run {
            runId jobName status creationTime startTime endTime tags { key value }
            stepStats { stepKey status startTime endTime } } } }"""
        return self.graphql(query, id=run_id)["runOrError"]

    def runs(self) -> list[dict]:
        """Every Dagster run, newest first: id, job, status, times and tags."""
        query = """{ runsOrError { ... on Runs { results {
            runId jobName status creationTime startTime endTime tags { key value } } } } }"""
        return self.graphql(query)["runsOrError"]["results"]

    def asset(self, name: str, materializations: int = 5) -> dict:
        """An asset as Dagster sees it: ``staleStatus`` and its latest materialisations
        (``runId``, ``timestamp`` in ms), newest first."""
        query = """query($key: [String!]!, $n: Int) {
            assetNodeOrError(assetKey: {path: $key}) { ... on AssetNode {
                staleStatus assetMaterializations(limit: $n) { runId timestamp } } } }"""
        return self.graphql(query, key=[name], n=materializations)["assetNodeOrError"]

    def cli(self, *args: str, timeout: float = 300.0) -> subprocess.CompletedProcess:
        """``python -m pwa_pipeline <args>`` on these stores, as the README's user types it
        (its output captured, stdout and stderr together)."""
        return subprocess.run([sys.executable, "-m", "pwa_pipeline", *args], cwd=ROOT,
                              env=self.env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                              stdin=subprocess.DEVNULL, text=True, timeout=timeout)


@contextmanager
def ui_stack(root: Path) -> Iterator[UIStack]:
    """A started :class:`UIStack`, stopped on the way out, even on an error."""
    stack = UIStack(Path(root))
    try:
        yield stack.start()
    finally:
        stack.stop()


@contextmanager
def chromium() -> Iterator:
    """A headless Debian chromium driven by playwright (closed on the way out)."""
    problem = missing_browser()
    if problem:
        raise RuntimeError(problem)
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            yield browser
        finally:
            browser.close()


# --------------------------------------------------------------------------- what a user does

def launch_from_sweep(page, stack: UIStack, dataset: str, hparams: str) -> str:
    """*Jobs → sweep → Materialize all…*, pick one partition, *Launch 1 run*; the run id."""
    page.goto(f"{stack.dagster_url}/locations/{LOCATION}/jobs/sweep")
    page.get_by_role("button", name="Materialize all…").click()
    dialog = page.get_by_role("dialog").first
    dialog.get_by_text("Select a partition or create one").first.click()
    page.locator("[role=dialog]").nth(1).get_by_text(f"{dataset}|{hparams}", exact=True) \
        .first.click()
    dialog.get_by_text("Launch runs to materialize").click()  # closes the list
    page.get_by_role("button", name="Launch 1 run").click()
    toast = page.get_by_text("Launched run")
    toast.wait_for(timeout=30_000)
    page.get_by_role("link", name="View").or_(page.get_by_role("button", name="View")) \
        .first.click()
    page.wait_for_url("**/runs/*", timeout=30_000)
    return page.url.rstrip("/").split("/runs/")[1].split("?")[0]


#: How the run page labels each final status.
_ENDED = {"SUCCESS": "Success", "FAILURE": "Failure", "CANCELED": "Canceled"}


def wait_for_run(page, stack: UIStack, run_id: str, timeout: float = 300.0) -> dict:
    """Watch the run's page until it ends; the run as the API reports it."""
    page.goto(f"{stack.dagster_url}/runs/{run_id}")
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < timeout:
        run = stack.run(run_id)
        if run["status"] in _ENDED:
            page.reload()  # and wait for the page to say so
            page.get_by_text(_ENDED[run["status"]], exact=True).first.wait_for(timeout=60_000)
            return run
        time.sleep(1)
    raise TimeoutError(f"run {run_id} not finished after {timeout:.0f} s")


def watch_live_run(page, stack: UIStack, run_id: str, timeout: float = 300.0
                   ) -> tuple[dict, set[str]]:
    """Watch the run's page, never reloading it, until the run has ended and the page says
    so; returns the run as the API reports it and the steps the page listed under
    *Executing* while the API said the run was going."""
    page.goto(f"{stack.dagster_url}/runs/{run_id}")
    executing: set[str] = set()
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < timeout:
        run = stack.run(run_id)
        lines = [line.strip() for line in page.inner_text("body").splitlines() if line.strip()]
        if run["status"] == "STARTED":
            start = next((i for i, line in enumerate(lines) if line.startswith("Executing (")),
                         None)
            if start is not None:
                end = next(i for i in range(start, len(lines)) if lines[i].startswith("Errored"))
                executing |= {line for line in lines[start + 1:end]
                              if line.replace("_", "").isalnum()}
        if run["status"] in _ENDED and _ENDED[run["status"]] in lines:
            return run, executing
        time.sleep(0.3)
    raise TimeoutError(f"run {run_id}: its page did not show its end within {timeout:.0f} s")


def open_figure(page, stack: UIStack, asset: str, key: str):
    """The asset page's Markdown metadata ``key`` opened (*Show Markdown*); its <img>."""
    page.goto(f"{stack.dagster_url}/assets/{asset}")
    row = page.locator("tr", has=page.get_by_text(key, exact=True))
    row.get_by_text("[Show Markdown]").first.click()
    image = page.get_by_role("dialog").locator("img").first
    image.wait_for()
    page.wait_for_function("i => i.complete", arg=image.element_handle())
    return image


#: ``[decoded, naturalWidth, naturalHeight, drawn at the bottom]`` of an <img>: whether the
#: browser decoded it, its size, and whether its bottom quarter holds a dark pixel (axis
#: labels; a truncated PNG decodes too, but leaves its lower part empty).
_IMAGE_STATE = """async i => {
    const decoded = await i.decode().then(() => true, () => false);
    if (!decoded || !i.naturalWidth) return [decoded, i.naturalWidth, i.naturalHeight, false];
    const c = document.createElement("canvas");
    c.width = i.naturalWidth; c.height = i.naturalHeight;
    const g = c.getContext("2d");
    g.drawImage(i, 0, 0);
    const top = Math.floor(c.height * 0.75);
    const px = g.getImageData(0, top, c.width, c.height - top).data;
    let dark = false;
    for (let k = 0; k < px.length && !dark; k += 4)
        dark = px[k + 3] > 200 && px[k] + px[k + 1] + px[k + 2] < 300;
    return [decoded, i.naturalWidth, i.naturalHeight, dark];
}"""


def image_state(image) -> tuple[bool, int, int, bool]:
    """What the browser made of an <img>: decoded, natural width and height, and whether its
    bottom quarter is drawn (see ``_IMAGE_STATE``)."""
    return tuple(image.evaluate(_IMAGE_STATE))


def mlflow_experiment_id(stack: UIStack, dataset: str) -> str:
    from mlflow.tracking import MlflowClient

    return MlflowClient(stack.tracking_uri).get_experiment_by_name(
        f"pwa-pipeline/{dataset}").experiment_id


def mlflow_runs_url(stack: UIStack, experiment_id: str, search: str = "",
                    charts: bool = False) -> str:
    """The runs view of an experiment, as the README links it; ``search`` fills its search
    box (``tags.hparams = 'paper'``), ``charts`` opens its chart view."""
    url = f"{stack.mlflow_url}/#/experiments/{experiment_id}/runs{MLFLOW_TRAINING_VIEW}"
    if search:
        url += f"&searchFilter={quote(search)}"
    return url + ("&compareRunsMode=CHART" if charts else "")


def compare_all_runs(page) -> None:
    """On a runs view: select every run (the header's box) and click *Compare*."""
    page.get_by_role("checkbox").first.check()
    page.get_by_role("button", name="Compare").click()
    page.wait_for_url("**/compare-runs?**")


def mlflow_popups(page) -> list[str]:
    """What MLflow 3.17 puts over a page on a first visit and is shown now: its assistant's
    panel (opened by itself on the first page), a dialog (the model registry's
    announcement) and the GenAI tour's tip (*Got it*)."""
    shown = []
    if _visible(_ASSISTANT(page)):
        shown.append("assistant panel")
    for dialog in page.get_by_role("dialog").all():
        if dialog.is_visible():
            shown.append(f"dialog: {dialog.inner_text().strip().splitlines()[0]}")
    if _visible(page.get_by_role("button", name="Got it")):
        shown.append("tip")
    return shown


#: Where MLflow's UI notes that its assistant opened itself, on a browser's first page.
_ASSISTANT_OPENED = "mlflow.assistant.fab.autoOpenedOnFirstLoad_v1"


def dismiss_mlflow_popups(page, settle_ms: int = 1000) -> list[str]:
    """Close :func:`mlflow_popups` the way a user does, once the assistant has opened itself
    (or within 5 s) and ``settle_ms`` later (the registry's announcement comes within a
    second of the page's content); returns what was closed. The browser keeps them closed
    for the rest of the session."""
    from playwright.sync_api import TimeoutError as PlaywrightTimeout

    try:
        page.wait_for_function(f"() => localStorage.getItem({_ASSISTANT_OPENED!r}) !== null",
                               timeout=5_000)
    except PlaywrightTimeout:  # an MLflow without the assistant
        pass
    page.wait_for_timeout(settle_ms)
    closed = mlflow_popups(page)
    for dialog in page.get_by_role("dialog").all():
        if dialog.is_visible():
            dialog.get_by_role("button", name="Close").first.click()
    if _visible(_ASSISTANT(page)):
        # the panel's own close button: the one outside any dialog
        next(b for b in page.get_by_role("button", name="Close").all() if b.is_visible()).click()
    if _visible(page.get_by_role("button", name="Got it")):
        page.get_by_role("button", name="Got it").first.click()
    if closed:
        page.wait_for_timeout(300)  # the panel slides away
    return closed


def _ASSISTANT(page):  # noqa: N802
    """The assistant panel's question box (closed, the panel leaves a button labelled
    *MLflow Assistant* at the corner)."""
    return page.get_by_placeholder("Ask a question")


def _visible(locator) -> bool:
    return any(item.is_visible() for item in locator.all())


def mlflow_run_page(page) -> dict:
    """What an MLflow run's page (its *Overview*) shows: ``description``, ``metrics``
    (``{name: value as shown}``) and ``duration`` (as shown, e.g. ``6.9s``)."""
    page.get_by_text("Duration", exact=True).first.wait_for()
    lines = [line.strip() for line in page.inner_text("body").splitlines() if line.strip()]
    top = lines.index("Description")
    metrics_at = next(i for i, line in enumerate(lines) if re.fullmatch(r"Metrics \(\d+\)", line))
    end = next(i for i in range(metrics_at, len(lines)) if lines[i].startswith("Parameters ("))
    rows = lines[metrics_at + 1:end]
    if rows[:2] == ["Metric", "Value"]:
        rows = rows[2:]
    return {"description": " ".join(lines[top + 1:metrics_at]),
            "metrics": dict(zip(rows[::2], rows[1::2], strict=True)),
            "duration": lines[lines.index("Duration") + 1]}


def duration_seconds(shown: str) -> float:
    """MLflow's duration as shown (``244ms``, ``6.9s``, ``1.7min``, ``2.1h``) in seconds."""
    value, unit = re.fullmatch(r"([\d.]+)\s*(ms|s|min|h|d)", shown.strip()).groups()
    return float(value) * {"ms": 1e-3, "s": 1, "min": 60, "h": 3600, "d": 86400}[unit]


def significant_digits(shown: str) -> int:
    """How many significant digits a number as shown carries (``0.01539`` → 4, ``4.075`` →
    4, ``2`` → 1, ``1e+30`` → 1, ``0.421638102396945`` → 15)."""
    mantissa = re.split(r"[eE]", shown.strip().lstrip("+-−"))[0]
    digits = mantissa.replace(".", "").lstrip("0")
    return len(digits.rstrip("0")) if "." not in mantissa else len(digits) or 1


def collapse_chart_sections(page, *names: str) -> None:
    """In a runs view's chart view: fold the sections ``names`` (one per metric prefix,
    e.g. ``per_output``), as a user clicks their headers."""
    for name in names:
        page.get_by_text(name, exact=True).first.click()
    page.wait_for_timeout(500)


def search_charts(page, pattern: str) -> None:
    """In a runs view's chart view: type ``pattern`` in *Search metric charts* (a regular
    expression, case-insensitive: ``^(one_step|free_run)_nrmse$``), leaving the charts whose
    metric it matches."""
    page.get_by_placeholder("Search metric charts").fill(pattern)
    page.wait_for_timeout(800)


#: The texts of the chart card titled ``title``: its title, then its bars' labels and its
#: axes' tick labels (a card's plot is drawn once it is scrolled into view).
_CHART_TEXTS = """title => {
    const heads = [...document.querySelectorAll("h1, h2, h3, h4, h5, span, div")].filter(
        e => e.childElementCount === 0 && e.textContent === title);
    for (const head of heads) {
        let card = head;
        while (card && !card.querySelector("svg.main-svg")) card = card.parentElement;
        if (card) return [...card.querySelectorAll("svg text")].map(t => t.textContent);
    }
    return null;
}"""


def chart_numbers(page, title: str) -> list[str]:
    """The numbers drawn in the chart titled ``title`` of a chart view (bar labels and axis
    ticks, as shown), waiting for its plot to be drawn."""
    page.get_by_text(title, exact=True).first.scroll_into_view_if_needed()
    page.wait_for_function(f"() => ({_CHART_TEXTS})({json.dumps(title)})?.length > 0")
    texts = page.evaluate(_CHART_TEXTS, title)
    return [t.replace("−", "-") for t in texts if re.fullmatch(r"[-−+]?[\d.]+(e[-+]?\d+)?", t)]


def open_in_app(page, path: str) -> None:
    """Go to ``path`` inside the single-page app already open (Dagster's), as its own links
    do: no reload of the app."""
    page.evaluate("p => { history.pushState({}, '', p); "
                  "dispatchEvent(new PopStateEvent('popstate')); }", path)
    page.wait_for_url(f"**{path}")


# --------------------------------------------------------------------------- the asset graph

def open_asset_graph(page, stack: UIStack, assets: int) -> dict:
    """*Lineage*: the global asset graph top to bottom with every group expanded, zoomed out
    until all ``assets`` are in view (the graph draws only the nodes in view); the bounding
    box of each asset's node by its label (a long name is shortened in the middle:
    ``output…_refinement``)."""
    page.goto(f"{stack.dagster_url}/asset-groups")
    page.get_by_text("identification").first.wait_for()
    for item in ("Change graph to vertical orientation", "Expand all groups"):
        page.locator("[aria-label=settings]").last.click()  # the graph's settings
        page.get_by_role("menuitem", name=item).click()
        page.keyboard.press("Escape")
    page.goto(f"{stack.dagster_url}/asset-groups")  # laid out anew with those choices
    nodes = page.locator("foreignObject[style]")  # one per asset; groups carry a class
    nodes.first.wait_for()
    page.wait_for_timeout(500)  # laid out and zoomed to its centre
    # the graph's part of the page: below its toolbar (that of *Materialize all…*)
    bar = page.get_by_role("button", name="Materialize all…").first.bounding_box()
    top, (width, height) = bar["y"] + bar["height"] + 8, page.viewport_size.values()
    for _ in range(6):  # each click zooms out by a fixed step; nodes too small are not drawn
        boxes = {node.text_content(): node.bounding_box() for node in nodes.all()}
        if len(boxes) >= assets and all(b and b["y"] >= top and b["x"] >= 0 and b["x"] +
                                        b["width"] <= width and b["y"] + b["height"] <= height
                                        for b in boxes.values()):
            break
        page.locator("[aria-label=zoom_out]").last.click()
        page.wait_for_timeout(400)
    return boxes
