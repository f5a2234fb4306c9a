"""The viewer on the whole stack as a user starts it (``aisle run --demo``): the simulated robot is drawn where the
occupancy stage says it is, and the map grows on the page without a reload."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.helpers import wait_for
from tests.stack import aisle_run
from tests.viewer.browser import chromium, console_problems, open_viewer, wait_until

pytestmark = pytest.mark.slow


def test_the_demo_robot_and_its_growing_map_show_live(tmp_path: Path) -> None:
    # the stack stops with the page still open (its event stream is cut), as when a user presses Ctrl-C
    with aisle_run(tmp_path, "--demo", "--demo-rate", "3") as client, chromium() as driver:
        wait_for(lambda: client.get("/v1/maps/site/robots").status_code == 200
                 and client.get("/v1/maps/site/robots").json()["robots"], timeout_s=90, what="a robot stored")
        open_viewer(driver, str(client.base_url) + "/")
        driver.execute_script("window.notReloaded = true")
        first = int(driver.find_element("id", "revision-id").text)
        wait_until(driver, f"return Number(document.getElementById('revision-id').textContent) > {first}",
                   timeout_s=30, what="a newer revision shown")
        assert driver.execute_script("return window.notReloaded") is True
        assert driver.execute_script("return document.querySelectorAll('img.aisle-layer-occupancy').length") == 1
        wait_until(driver, "return document.querySelector('#layers li[data-layer=robots] .count').textContent "
                           "=== '(1)'", timeout_s=5, what="the robot in the legend")
        robot = client.get("/v1/maps/site/robots").json()["robots"][0]
        assert robot["track"] and robot["robot"]
        assert console_problems(driver) == []
