"""A real headless Chromium driven by Selenium, and the API served over real HTTP, for the viewer's tests.

Debian's ``chromium`` and ``chromium-driver`` are used where they are installed (nothing downloads a browser:
Selenium is given the driver's path, so its manager never runs); tests skip and say why without them.
"""

from __future__ import annotations

import shutil
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest
import uvicorn
from fastapi import FastAPI

from tests.helpers import free_port, wait_for

CHROMIUM = "/usr/bin/chromium"
CHROMEDRIVER = "/usr/bin/chromedriver"
WINDOW = (1400, 900)


@contextmanager
def chromium() -> Iterator[Any]:
    """A headless Chromium session (selenium ``WebDriver``) that keeps the page's console log; skips without one."""
    selenium = pytest.importorskip("selenium", reason="selenium is not installed (pip install -e '.[dev]')")
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    for path, package in ((CHROMIUM, "chromium"), (CHROMEDRIVER, "chromium-driver")):
        if shutil.which(path) is None:
            pytest.skip(f"no {path}: browser tests need Debian's {package} (apt-get install -y chromium "
                        f"chromium-driver; .ci/run installs them when it runs as root)")
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for argument in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--disable-gpu",
                     f"--window-size={WINDOW[0]},{WINDOW[1]}", "--force-device-scale-factor=1"):
        options.add_argument(argument)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
    assert selenium.__version__
    try:
        yield driver
    finally:
        driver.quit()


@contextmanager
def serving(app: FastAPI, *, port: int | None = None) -> Iterator[str]:
    """``app`` served by uvicorn on loopback (on ``port``, default a free one) in a thread; yields its base URL.

    Open event streams are cut a second after the server is told to stop.
    """
    port = free_port() if port is None else port
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning", lifespan="on",
                                           timeout_graceful_shutdown=1))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    try:
        wait_for(lambda: server.started, timeout_s=20, what="uvicorn to start")
        yield f"http://127.0.0.1:{port}"
    finally:
        server.should_exit = True
        thread.join(timeout=20)


def open_viewer(driver: Any, url: str, *, timeout_s: float = 20.0) -> None:
    """Load the viewer at ``url`` and wait until it has drawn the map."""
    driver.get(url)
    wait_until(driver, "return !!(window.aisleViewer && window.aisleViewer.ready)", timeout_s=timeout_s,
               what="the viewer to draw the map")


def wait_until(driver: Any, script: str, *, timeout_s: float = 10.0, what: str = "the page") -> Any:
    """Run ``script`` in the page until it returns something truthy; that value."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = driver.execute_script(script)
        if value:
            return value
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {timeout_s} s waiting for {what}")
        time.sleep(0.05)


def console_problems(driver: Any, *, allowed: tuple[str, ...] = ()) -> list[str]:
    """Warnings and errors the page logged since the last call (and failed requests), but those containing
    one of ``allowed``."""
    return [entry["message"] for entry in driver.get_log("browser")
            if entry["level"] in {"SEVERE", "WARNING"} and not any(text in entry["message"] for text in allowed)]
