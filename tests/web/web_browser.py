"""A headless Chromium driven by selenium for the page's tests: Debian's chromium and chromedriver
(``/usr/bin/chromedriver``, never one downloaded: the machine's network is closed), a fresh profile each."""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager

import pytest

CHROMEDRIVER = "/usr/bin/chromedriver"
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-dev-shm-usage", "--window-size=1400,1000")


def chromium() -> str:
    """The browser's path, or the test fails saying what to install (never a skip)."""
    for name in ("chromium", "chromium-browser"):
        path = shutil.which(name)
        if path and os.path.exists(CHROMEDRIVER):
            return path
    pytest.fail("the page's tests need Debian's chromium and chromium-driver (/usr/bin/chromium, "
                f"{CHROMEDRIVER}): apt-get install -y chromium chromium-driver (.ci/run does)")


@contextmanager
def browser() -> Iterator:
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    binary = chromium()
    options = webdriver.ChromeOptions()
    options.binary_location = binary
    for flag in FLAGS:
        options.add_argument(flag)
    profile = tempfile.mkdtemp(prefix="ncfmu-chromium-")
    options.add_argument(f"--user-data-dir={profile}")
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    # the driver given, so selenium-manager never runs (it would try to download one)
    driver = webdriver.Chrome(options=options, service=Service(executable_path=CHROMEDRIVER))
    try:
        yield driver
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)
