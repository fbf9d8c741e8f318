"""Fixtures shared by the system tests."""

import pytest

from benchmarks._ui import chromium, missing_browser


@pytest.fixture(scope="module")
def browser(system_package):
    """Debian's chromium driven by pip's playwright (the tests skip, saying how to install
    it, where it is missing)."""
    system_package("the browser tests need playwright and chromium", missing_browser())
    with chromium() as browser:
        yield browser
