"""The documentation site as a reader sees it: built by ``mkdocs build --strict`` into a
temporary folder, served on loopback and opened page by page in Debian's chromium (pip's
playwright), after MathJax has typeset each page's formulas.

Every page's prose (code aside, which shows markup as it is written) must be free of what a
renderer left raw: Sphinx roles (``:meth:`` …) and reST literals (two backticks) that
mkdocstrings does not render, mkdocstrings cross-references that found no target and LaTeX
that MathJax did not typeset; and its inline code of a table's escaped pipe (``\\|``), shown
as written there, where a reader copies it. MathJax comes from a CDN on the published
site; here its requests are answered from the same version installed by npm
(``npm install --no-save mathjax@<version of mkdocs.yml>`` in the repository, as ``.ci/run``
does), and every other request leaving loopback is refused, so the test runs offline. A
screenshot of the API reference and of the control page goes to the directory printed at the
start (``$PWA_SCREENSHOTS`` to choose it).
"""

import functools
import http.server
import json
import os
import re
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

import pytest

from benchmarks._ui import VIEWPORT

pytestmark = [pytest.mark.browser, pytest.mark.xdist_group("docs-site")]

ROOT = Path(__file__).resolve().parents[2]
#: The MathJax script of ``mkdocs.yml``: its CDN prefix and version.
MATHJAX_URL = re.compile(r"(https://\S+/mathjax@(\d+\.\d+\.\d+))/(\S+\.js)")
#: What a renderer left raw in prose, by what it is (code shows markup as written).
RAW = {
    "Sphinx role": re.compile(r":(?:meth|class|func|attr|mod|data|obj|exc|ref):"),
    "reST literal": re.compile(r"``"),
    "unresolved cross-reference": re.compile(r"\]\[[\w.]+\]"),
    "LaTeX": re.compile(r"\\frac|\$\$|\\\(|\\\[|\\begin\{"),
    "machine load": re.compile(r"load average|1-minute load"),
}
#: What a renderer left raw inside inline code: a table's escaped pipe, which the reader copies.
RAW_IN_CODE = {"escaped table pipe": re.compile(r"\\\|")}
#: A page's prose (no code, no code listings, no MathJax output) and its inline code.
RENDERED_TEXT = """() => {
    const body = document.body.cloneNode(true);
    body.querySelectorAll("pre, script, style, mjx-container, code").forEach(e => e.remove());
    const code = Array.from(document.querySelectorAll(":not(pre) > code"), e => e.textContent);
    return {prose: body.textContent, code: code.join("\\n")};
}"""
#: Resolves once MathJax has typeset the page (at once where the page loads no MathJax).
TYPESET = """async () => {
    if (!window.MathJax) return 0;
    for (let i = 0; i < 200 && !(MathJax.startup && MathJax.startup.promise); i++)
        await new Promise(r => setTimeout(r, 50));
    await MathJax.startup.promise;
    return document.querySelectorAll("mjx-container").length;
}"""


def raw_markup(prose: str, code: str = "") -> dict[str, list[str]]:
    """``{kind: [the raw markup with a few characters around it, ...]}`` found in a page's
    ``prose`` and inline ``code``."""
    found: dict[str, list[str]] = {}
    for text, patterns in ((prose, RAW), (code, RAW_IN_CODE)):
        for kind, pattern in patterns.items():
            for match in pattern.finditer(text):
                around = text[max(0, match.start() - 40):match.end() + 40]
                found.setdefault(kind, []).append(" ".join(around.split()))
    return found


def test_raw_markup_is_found():
    """The patterns catch each kind of raw markup, and not rendered prose."""
    assert set(raw_markup("see :meth:PWARX.paper and ``x``")) == {"Sphinx role", "reST literal"}
    assert set(raw_markup("\\[ \\frac{a}{b} \\]")) == {"LaTeX"}
    assert set(raw_markup("taken under 1-minute load average 1.20")) == {"machine load"}
    assert set(raw_markup("fitted [`X`][pwa_pipeline.pwa.X]")) == {"unresolved cross-reference"}
    assert set(raw_markup("", "--partition 'kuka_robot\\|paper'")) == {"escaped table pipe"}
    assert raw_markup("H_i z ≤ h_i, x(k+1) = A_i x(k) [y1; y2]: a ratio",
                      "--partition 'kuka_robot|paper'") == {}


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    pytest.importorskip("mkdocs", reason="mkdocs is not installed: pip install -e '.[docs]'")
    pytest.importorskip("mkdocstrings", reason="mkdocstrings is not installed: pip install -e '.[docs]'")
    out = tmp_path_factory.mktemp("docs") / "site"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
           "NO_MKDOCS_2_WARNING": "1"}
    result = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file", str(ROOT / "mkdocs.yml"),
         "--site-dir", str(out)], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    return out


@pytest.fixture(scope="module")
def mathjax(system_package) -> tuple[str, Path]:
    """The CDN prefix of ``mkdocs.yml``'s MathJax and the folder of the same version from npm."""
    match = MATHJAX_URL.search((ROOT / "mkdocs.yml").read_text())
    assert match, "mkdocs.yml loads no pinned MathJax (https://…/mathjax@X.Y.Z/…js)"
    prefix, version = match.group(1), match.group(2)
    local = ROOT / "node_modules" / "mathjax"
    package = local / "package.json"
    installed = json.loads(package.read_text())["version"] if package.is_file() else None
    system_package(f"the docs-site test needs MathJax {version} from npm",
                   None if installed == version else
                   f"found {installed or 'none'} in {local}; run `npm install --no-save "
                   f"--no-package-lock mathjax@{version}` in the repository")
    return prefix, local


@pytest.fixture(scope="module")
def served(site) -> str:
    """The built site on a loopback HTTP server (its URL), stopped on the way out."""
    handler = functools.partial(_QuietHandler, directory=str(site))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}"
    finally:
        server.shutdown()
        server.server_close()


class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, format, *args):
        pass


@pytest.fixture(scope="module")
def shots() -> Path:
    path = Path(os.environ.get("PWA_SCREENSHOTS") or tempfile.mkdtemp(prefix="pwa-docs-"))
    path.mkdir(parents=True, exist_ok=True)
    print(f"\ndocs-site screenshots in {path}")
    return path


@pytest.fixture(scope="module")
def page(browser, served, mathjax):
    """A page whose requests go to the served site or, for MathJax, to the npm copy."""
    prefix, local = mathjax
    context = browser.new_context(viewport=VIEWPORT)

    def route(request_route):
        url = request_route.request.url
        if url.startswith(served):
            return request_route.continue_()
        if url.startswith(prefix + "/"):
            return request_route.fulfill(path=str(local / url[len(prefix) + 1:].split("?")[0]))
        return request_route.abort()  # offline: fonts and anything else from outside

    context.route("**/*", route)
    page = context.new_page()
    page.set_default_timeout(30_000)
    yield page
    context.close()


#: Where each photographed page is shown: the estimator's docstring with its cross-references,
#: the state-space model typeset by MathJax.
SHOWN = {"api": "a.autorefs-internal", "control": "mjx-container"}


def _pages(site: Path) -> list[str]:
    return sorted(str(p.parent.relative_to(site)) for p in site.rglob("index.html")
                  if "search" not in p.parts)


def test_every_page_renders(site, served, page, shots):
    """No page shows a raw role, literal, cross-reference or formula; the control page's
    state-space model is typeset by MathJax."""
    pages = _pages(site)
    assert {"api", "control", "getting-started"} <= set(pages), pages
    raw, typeset = {}, {}
    for name in pages:
        page.goto(f"{served}/{'' if name == '.' else name + '/'}")
        typeset[name] = page.evaluate(TYPESET)
        text = page.evaluate(RENDERED_TEXT)
        found = raw_markup(text["prose"], text["code"])
        if found:
            raw[name] = found
        if name in SHOWN:
            shown = page.locator(SHOWN[name])
            if shown.count():  # else the assertions below say what is missing
                shown.first.evaluate("e => e.scrollIntoView({block: 'center'})")
            page.wait_for_timeout(500)  # the header's title fades in on scrolling
            page.screenshot(path=shots / f"docs-{name}.png")
    assert not raw, json.dumps(raw, indent=1, ensure_ascii=False)
    assert typeset["control"] >= 1, "MathJax typeset nothing on the control page"


def test_api_reference_links_its_cross_references(served, page):
    """The docstrings' cross-references became links to the objects they name."""
    page.goto(f"{served}/api/")
    links = page.locator("a.autorefs-internal")
    assert links.count() >= 100, links.count()
    paper = page.locator("a.autorefs-internal", has_text="PWARX.paper").first
    assert paper.get_attribute("href").endswith("#pwa_pipeline.PWARX.paper")
