"""The map viewer as a person uses it: a real headless Chromium on the API served over HTTP.

The map is the small simulated warehouse of ``tests/api/warehouse_map.py`` (its ground-truth occupancy decomposed
by the real grid decomposition, its bins as the pillar stage writes them) in a SQLite file, with a robot as the
occupancy stage stores it. One browser and one server serve the whole module.
"""

from __future__ import annotations

import base64
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import httpx2 as httpx
import numpy as np
import pytest

from api import create_app
from shared.bins import Bin
from shared.loads import BinOccupancy, Occupancy, write_scene_revision
from shared.robots import Robot, TrackPoint
from shared.settings import Settings
from shared.store import Feature, MapInfo, MapStore, RevisionWrite
from shared.store.keys import Role, create_key
from tests.api.warehouse_map import warehouse, write_warehouse
from tests.helpers import free_port
from tests.viewer.browser import chromium, console_problems, open_viewer, serving, wait_until

BIN_ID = "02-005-02"


class Site:
    def __init__(self, store: MapStore, info: MapInfo, url: str) -> None:
        self.store, self.info, self.url = store, info, url


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Site]:
    folder = tmp_path_factory.mktemp("viewer")
    store = MapStore(f"sqlite:///{folder / 'aisle.db'}")
    store.upgrade()
    info = write_warehouse(store)
    track = tuple(TrackPoint(2.0 + 0.5 * i, 1.5, 0.0, 1_000_000_000 * (i + 1)) for i in range(10))
    store.write_revision(info.id, RevisionWrite("occupancy_mapping", features={
        "robot": [Robot("robot1", track[-1], track).feature()]}))
    app = create_app(store=store, settings=Settings(data_dir=folder, database_url=store.url), event_poll_s=0.1)
    with serving(app) as url:
        yield Site(store, info, url)
    store.close()


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    with chromium() as driver:
        yield driver


@pytest.fixture
def page(browser: Any, site: Site) -> Iterator[Any]:
    """The viewer loaded afresh; after the test, the page must have logged no warning or error."""
    console_problems(browser)
    open_viewer(browser, site.url + "/")
    yield browser
    assert console_problems(browser) == []


@pytest.fixture(scope="module")
def write_key(site: Site) -> str:
    return create_key(site.store, role=Role.WRITE, name="viewer-writer")[1]


@pytest.fixture
def writer(page: Any, site: Site, write_key: str) -> Iterator[Any]:
    """The viewer loaded afresh with a write key in the tab's session storage (cleared afterwards)."""
    page.execute_script("sessionStorage.setItem('aisle.apiKey', arguments[0])", write_key)
    open_viewer(page, site.url + "/")
    yield page
    page.execute_script("sessionStorage.clear()")


def legend_count(driver: Any, layer: str) -> str:
    return str(driver.execute_script(
        f"return document.querySelector('#layers li[data-layer=\"{layer}\"] .count').textContent"))


def view_image(driver: Any) -> np.ndarray:
    """What the map shows now, as the viewer exports it (RGB)."""
    url = driver.execute_script("return window.aisleViewer.viewCanvas().toDataURL('image/png')")
    data = np.frombuffer(base64.b64decode(url.split(",", 1)[1]), np.uint8)
    image = cv2.imdecode(data, cv2.IMREAD_COLOR)
    assert image is not None, "the export is not a PNG"
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


def pixels_of(image: np.ndarray, rgb: tuple[int, int, int], tolerance: int = 40) -> int:
    return int((np.abs(image.astype(int) - np.array(rgb)).max(axis=2) <= tolerance).sum())


def click_at(driver: Any, x_m: float, y_m: float) -> None:
    """A person's click on the map at (x, y) metres."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    element = driver.find_element(By.ID, "map")
    point = driver.execute_script(f"return window.aisleViewer.leaflet.latLngToContainerPoint([{y_m}, {x_m}])")
    size = element.size
    ActionChains(driver).move_to_element_with_offset(
        element, int(point["x"] - size["width"] / 2), int(point["y"] - size["height"] / 2)).click().perform()


def test_the_page_is_served_from_the_package_with_nothing_from_elsewhere(site: Site) -> None:
    page_html = httpx.get(site.url + "/").text
    assert httpx.get(site.url + "/viewer").text == page_html
    assert "http://" not in page_html and "https://" not in page_html  # no CDN, fonts or tiles
    for asset in ("viewer.js", "bins.js", "viewer.css", "leaflet/leaflet.js", "leaflet/LICENSE"):
        assert httpx.get(f"{site.url}/viewer/{asset}").status_code == 200
    assert "Leaflet 1.9.4" in httpx.get(site.url + "/viewer/leaflet/leaflet.js").text
    assert httpx.get(site.url + "/viewer/../api/app.py").status_code == 404


def test_every_layer_is_listed_with_its_count_and_toggles(page: Any, site: Site) -> None:
    bins = site.store.features(site.info.id, kinds=["bin"])
    assert legend_count(page, "bins") == f"({len(bins)})"
    assert legend_count(page, "places") == "(3)"  # two docks and a charger
    assert legend_count(page, "robots") == "(1)"
    assert legend_count(page, "floorplan") == "(0)"  # no floor-plan stage ran: listed, empty
    regions = site.store.features(site.info.id, kinds=["corridor", "junction", "room", "open_area", "region"])
    assert legend_count(page, "regions") == f"({len(regions)})"
    legend = page.execute_script("return [...document.querySelectorAll('#layers li[data-layer=regions] .legend li')]"
                                 ".map(e => e.textContent)")
    assert {"corridor", "junction"} <= set(legend)
    assert page.execute_script("return document.querySelectorAll('img.aisle-layer-occupancy').length") == 1
    bin_orange = pixels_of(view_image(page), (242, 202, 147), tolerance=12)
    assert bin_orange > 1000  # the bins are drawn

    page.execute_script("document.querySelector('input[data-layer=bins]').click()")
    assert page.execute_script("return document.querySelectorAll('canvas[data-layer=bins]').length") == 0
    assert pixels_of(view_image(page), (242, 202, 147), tolerance=12) < bin_orange / 10
    page.execute_script("document.querySelector('input[data-layer=occupancy]').click()")
    assert page.execute_script("return document.querySelectorAll('img.aisle-layer-occupancy').length") == 0
    page.execute_script("document.querySelector('input[data-layer=bins]').click()")
    assert page.execute_script("return document.querySelectorAll('canvas[data-layer=bins]').length") == 1


def test_a_bin_found_by_id_is_flown_to_and_its_card_matches_the_store(page: Any, site: Site) -> None:
    state = BinOccupancy(BIN_ID, Occupancy.OCCUPIED, 0.97, time.time_ns(), ("p1", "l1"), views=3, bay="r0/1")
    written = write_scene_revision(site.store, site.info.id, [], [state])
    assert written.bins_changed == (BIN_ID,) and written.revision is not None
    wait_until(page, f"return Number(document.getElementById('revision-id').textContent) >= {written.revision.id}",
               timeout_s=5, what="the scene revision on the page")  # the API has it: ask after that
    page.find_element("id", "bin-query").send_keys(BIN_ID + "\n")
    wait_until(page, f"return document.getElementById('card-title').textContent === 'Bin {BIN_ID}'",
               what="the bin's card")
    card = page.execute_script("return Object.fromEntries([...document.querySelectorAll('#card-body tr')]"
                               ".map(r => [r.dataset.field, r.cells[1].textContent]))")
    stored = site.store.feature(site.info.id, "bin", BIN_ID)
    assert stored is not None
    record = Bin.from_feature(stored.feature)
    assert record.access_pose is not None and record.opening is not None
    assert card["id"] == BIN_ID
    assert card["aisle"] == str(record.aisle) and card["level"] == str(record.level)
    assert card["access pose"].startswith(f"({record.access_pose.x_m:.2f}, {record.access_pose.y_m:.2f})")
    assert card["opening"].startswith(f"{record.opening.width_m:.2f} m")
    assert card["confidence"] == f"{stored.feature.confidence:.2f}"
    assert card["occupancy"].startswith("occupied (0.97, 3 views, seen ") and card["occupancy"].endswith(": p1, l1")
    # the view flies to the bin
    x, y = record.centre
    wait_until(page, f"const c = window.aisleViewer.leaflet.getCenter(); return Math.hypot(c.lng - {x}, c.lat - {y})"
                     " < 1 && window.aisleViewer.leaflet.getZoom() >= 5", what="the view to fly to the bin")


def test_a_click_on_a_bin_opens_its_card_and_elsewhere_says_what_is_there(page: Any, site: Site) -> None:
    stored = site.store.feature(site.info.id, "bin", BIN_ID)
    assert stored is not None
    x, y = Bin.from_feature(stored.feature).centre
    click_at(page, x, y)
    title = wait_until(page, "return document.getElementById('card-title').textContent.startsWith('Bin') && "
                             "document.getElementById('card-title').textContent", what="a bin card")
    assert title.split()[1][:6] == BIN_ID[:6]  # a bin of that footprint (the levels share it)
    access = Bin.from_feature(stored.feature).access_pose
    assert access is not None
    click_at(page, access.x_m, access.y_m)  # in the aisle in front of it
    wait_until(page, "return document.getElementById('card-title').textContent === 'At this point'",
               what="the semantics card")
    answer = httpx.get(f"{site.url}/v1/maps/site/semantics",
                       params={"x": f"{access.x_m:.3f}", "y": f"{access.y_m:.3f}"}).json()
    place = page.execute_script("return document.querySelector('#card-body tr[data-field=place] td+td').textContent")
    assert place.startswith(answer["place"]["label"])


def test_a_route_between_two_places_is_drawn_with_its_length(page: Any, site: Site) -> None:
    before = pixels_of(view_image(page), (0, 80, 255), tolerance=30)
    page.find_element("id", "route-from").send_keys(f"bin:{BIN_ID}")
    page.find_element("id", "route-to").send_keys("dock:G1\n")
    text = wait_until(page, "return document.getElementById('route-info').textContent", what="the route")
    route = httpx.get(f"{site.url}/v1/maps/site/routes", params={"from": f"bin:{BIN_ID}", "to": "dock:G1"}).json()
    assert text.startswith(f"{route['length_m']:.1f} m from bin:{BIN_ID} to dock:G1")
    assert pixels_of(view_image(page), (0, 80, 255), tolerance=30) > before + 200  # a blue line across the hall


def test_two_places_picked_on_the_map_get_a_route(page: Any) -> None:
    page.find_element("id", "route-pick").click()
    dock, charger = warehouse().world.gates[0], warehouse().world.chargers[0]
    click_at(page, (dock.a[0] + dock.b[0]) / 2, dock.a[1] + 0.3)
    click_at(page, float(charger.pose[0]), float(charger.pose[1]))
    text = wait_until(page, "return document.getElementById('route-info').textContent.includes(' m from ') && "
                            "document.getElementById('route-info').textContent", what="the picked route")
    assert "from dock:G1 to charger:C1" in text


def test_a_new_revision_appears_without_a_reload(page: Any, site: Site) -> None:
    page.execute_script("window.notReloaded = true")
    shown = int(page.find_element("id", "revision-id").text)
    revision = site.store.write_revision(site.info.id, RevisionWrite("ground_truth", features={
        "dock": [Feature("dock", "G1", {"type": "LineString", "coordinates": [[4.0, 0.0], [7.0, 0.0]]}),
                 Feature("dock", "G2", {"type": "LineString", "coordinates": [[23.0, 0.0], [26.0, 0.0]]}),
                 Feature("dock", "G3", {"type": "LineString", "coordinates": [[14.0, 0.0], [16.0, 0.0]]})],
        "charger": [Feature("charger", "C1", {"type": "Point", "coordinates": [1.0, 8.0]})],
        "robot": [Robot("robot2", TrackPoint(20.0, 1.5, 0.0, 5), (TrackPoint(20.0, 1.5, 0.0, 5),)).feature()]}))
    assert revision.id > shown
    wait_until(page, f"return document.getElementById('revision-id').textContent === '{revision.id}'",
               timeout_s=5, what="the new revision on the page")
    wait_until(page, "return document.querySelector('#layers li[data-layer=places] .count').textContent === '(4)'",
               timeout_s=2, what="the new dock drawn")
    wait_until(page, "return document.querySelector('#layers li[data-layer=robots] .count').textContent === '(2)'",
               timeout_s=2, what="the new robot drawn")
    assert page.execute_script("return window.notReloaded") is True
    asked = page.execute_script("return performance.getEntriesByType('resource').map(e => e.name)"
                                ".filter(n => n.includes('/layout?'))")
    assert asked and all("since=" in url and "kind=dock" in url and "kind=bin" not in url for url in asked)


def test_the_history_slider_shows_the_map_as_it_was_and_what_changed_since(page: Any, site: Site) -> None:
    decomposition = site.store.revisions(site.info.id, limit=2)[1].id  # before the bins were written
    page.execute_script(f"const s = document.getElementById('history'); s.value = {decomposition};"
                        "s.dispatchEvent(new Event('change'))")
    wait_until(page, f"return document.getElementById('history-label').textContent === 'as at revision "
                     f"{decomposition}'", what="the old revision")
    wait_until(page, "return document.querySelector('#layers li[data-layer=bins] .count').textContent === '(0)'",
               what="the bins gone (they came later)")
    diff = wait_until(page, "return document.getElementById('diff-info').textContent", what="the diff")
    bins = len(site.store.features(site.info.id, kinds=["bin"]))
    assert f"bin: +{bins}" in diff
    page.find_element("id", "history-live").click()
    wait_until(page, f"return document.querySelector('#layers li[data-layer=bins] .count').textContent === "
                     f"'({bins})'", what="back to live")


def test_the_view_exports_as_a_png_with_scale_bar_cursor_and_axes(page: Any) -> None:
    image = view_image(page)
    size = page.execute_script("const s = window.aisleViewer.leaflet.getSize(); return [s.x, s.y]")
    assert image.shape[:2] == (size[1], size[0])
    assert page.find_element("css selector", ".leaflet-control-scale-line").text.endswith("m")
    assert page.find_element("id", "axes").is_displayed()
    click_at(page, 10.0, 5.0)
    x_text, y_text = page.find_element("id", "cursor").text.replace(" m", "").replace("x ", "").split(", y ")
    assert abs(float(x_text) - 10.0) < 0.2 and abs(float(y_text) - 5.0) < 0.2


def test_the_page_asks_for_a_key_when_the_api_needs_one(browser: Any, site: Site, tmp_path: Path) -> None:
    guarded = create_app(store=site.store, settings=Settings(data_dir=tmp_path, database_url=site.store.url),
                         require_keys_for_reads=True)
    _, secret = create_key(site.store, role=Role.READ, name="viewer-test")
    with serving(guarded) as url:
        browser.get(url + "/")
        wait_until(browser, "return !document.getElementById('key-dialog').hidden", what="the key prompt")
        assert "needs an API key" in browser.find_element("id", "key-reason").text
        browser.find_element("id", "key-input").send_keys(secret + "\n")
        wait_until(browser, "return window.aisleViewer.ready", what="the map with the key")
        assert legend_count(browser, "bins") == f"({len(site.store.features(site.info.id, kinds=['bin']))})"
        assert browser.execute_script("return sessionStorage.getItem('aisle.apiKey')") == secret
        assert console_problems(browser, allowed=("401 (Unauthorized)",)) == []
        browser.execute_script("sessionStorage.clear()")
        browser.get("about:blank")


def test_after_a_server_restart_the_page_reconnects_and_catches_up(browser: Any, site: Site, tmp_path: Path) -> None:
    port = free_port()

    def app() -> Any:
        return create_app(store=site.store, settings=Settings(data_dir=tmp_path, database_url=site.store.url),
                          event_poll_s=0.1)

    with serving(app(), port=port) as url:
        open_viewer(browser, url + "/")
        browser.execute_script("window.notReloaded = true")
    wait_until(browser, "return document.getElementById('live-state').textContent === 'reconnecting'",
               what="the page to notice the server went away")
    missed = site.store.write_revision(site.info.id, RevisionWrite("ground_truth", features={
        "charger": [Feature("charger", "C1", {"type": "Point", "coordinates": [1.0, 8.0]}),
                    Feature("charger", "C2", {"type": "Point", "coordinates": [1.0, 12.0]})]})).id
    with serving(app(), port=port):
        wait_until(browser, f"return document.getElementById('revision-id').textContent === '{missed}'",
                   timeout_s=10, what="the revision written while the server was down")
        assert browser.execute_script("return document.getElementById('live-state').textContent") == "live"
        assert browser.execute_script("return window.notReloaded") is True
        browser.get("about:blank")
    assert console_problems(browser, allowed=("Failed to load resource", "ERR_CONNECTION_REFUSED",
                                              "ERR_INCOMPLETE_CHUNKED_ENCODING")) == []


def test_a_change_from_the_page_asks_for_a_write_key(browser: Any, site: Site) -> None:
    open_viewer(browser, site.url + "/")
    latest = site.store.latest_revision(site.info.id)
    stored = site.store.feature(site.info.id, "bin", BIN_ID)
    assert stored is not None
    access = Bin.from_feature(stored.feature).access_pose
    assert access is not None
    click_at(browser, access.x_m, access.y_m)
    wait_until(browser, "return document.querySelector('#card-actions button')", what="the block button")
    browser.find_element("css selector", "#card-actions button").click()
    wait_until(browser, "return !document.getElementById('key-dialog').hidden", what="the key prompt")
    assert "write key" in browser.find_element("id", "key-reason").text
    browser.find_element("id", "key-cancel").click()
    assert site.store.latest_revision(site.info.id) == latest  # nothing was written
    assert console_problems(browser, allowed=("401 (Unauthorized)",)) == []


def test_a_place_put_at_a_click_is_stored_drawn_and_removed_from_the_page(writer: Any, site: Site) -> None:
    page = writer
    before = legend_count(page, "places")
    page.find_element("id", "place-kind").send_keys("charger")
    page.find_element("id", "place-key").send_keys("C9")
    heading = page.find_element("id", "place-heading")
    heading.clear()
    heading.send_keys("90")
    page.find_element("id", "place-name").send_keys("Charger 9")
    page.find_element("css selector", "#place-form button[type=submit]").click()
    click_at(page, 12.0, 6.0)
    wait_until(page, "return (window.aisleViewer.state.features.charger || []).some(f => f.properties.key === 'C9')",
               what="the new charger drawn")
    assert legend_count(page, "places") == f"({int(before.strip('()')) + 1})"
    place = httpx.get(f"{site.url}/v1/maps/site/places/charger/C9").json()
    assert place["stage"] == "operator" and place["name"] == "Charger 9"
    x, y = place["geometry"]["coordinates"]
    assert abs(x - 12.0) < 0.2 and abs(y - 6.0) < 0.2  # where it was clicked
    assert abs(place["approach_pose"]["yaw_rad"] - np.pi / 2) < 1e-3  # the heading given, as radians
    assert "revision" in page.find_element("id", "place-info").text

    page.find_element("id", "place-remove").click()
    wait_until(page, "return !(window.aisleViewer.state.features.charger || []).some(f => f.properties.key === 'C9')",
               what="the charger gone from the map")
    assert legend_count(page, "places") == before
    assert httpx.get(f"{site.url}/v1/maps/site/places/charger/C9").status_code == 404


def test_a_blocked_region_and_aisle_are_unblocked_from_the_page(writer: Any, site: Site, write_key: str) -> None:
    page, blocked = writer, f"{site.url}/v1/maps/site/topology/blocked"
    headers = {"X-API-Key": write_key}
    region = site.store.features(site.info.id, kinds=["corridor"])[0].feature.key
    assert httpx.put(f"{blocked}/regions/{region}", json={"reason": "spill"}, headers=headers).status_code == 201
    button = f"document.querySelector('#blocks li[data-block=\"{region}\"] button')"
    wait_until(page, f"return {button}", what="the block listed")
    assert "spill" in page.find_element("css selector", "#blocks li").text
    page.execute_script(f"{button}.click()")  # unblocked from the list of blocks
    wait_until(page, "return !document.querySelector('#blocks li[data-block]')", what="the block gone from the list")
    assert httpx.get(blocked).json()["blocks"] == []

    stored = site.store.feature(site.info.id, "bin", BIN_ID)
    assert stored is not None
    access = Bin.from_feature(stored.feature).access_pose
    assert access is not None
    here = httpx.get(f"{site.url}/v1/maps/site/semantics", params={"x": access.x_m, "y": access.y_m}).json()
    outline = next(s.feature for s in site.store.features(site.info.id) if s.feature.key == here["place"]["region"])
    site.store.write_revision(site.info.id, RevisionWrite("pillar_mapping", features={  # an aisle, as the stage
        "corridor": [Feature("corridor", "aisle-01", outline.geometry, {"kind": "corridor", "aisle": 1})]}))
    assert httpx.put(f"{blocked}/regions/aisle-01", headers=headers).status_code == 201
    wait_until(page, "return document.querySelector('#blocks li[data-block=\"aisle-01\"]')", what="the aisle block")
    click_at(page, access.x_m, access.y_m)  # unblocked from the card of a point in the aisle
    wait_until(page, "return [...document.querySelectorAll('#card-actions button')]"
                     ".some(b => b.textContent === 'Unblock aisle-01')", what="the card's unblock button")
    page.execute_script("[...document.querySelectorAll('#card-actions button')]"
                        ".find(b => b.textContent === 'Unblock aisle-01').click()")
    wait_until(page, "return !document.querySelector('#blocks li[data-block]')", what="the aisle block gone")
    assert httpx.get(blocked).json()["blocks"] == []
    graph = httpx.get(f"{site.url}/v1/maps/site/topology", params={"format": "geojson"}).json()
    assert not any(f["properties"].get("blocked") for f in graph["features"])
    site.store.write_revision(site.info.id, RevisionWrite("pillar_mapping", features={"corridor": []}))


def test_a_label_table_edit_without_a_key_asks_for_one_and_is_stored(page: Any, site: Site, write_key: str) -> None:
    from selenium.webdriver.support.ui import Select

    page.find_element("id", "labels-toggle").click()
    wait_until(page, "return document.querySelectorAll('#labels-table select').length", what="the label table")
    table = httpx.get(f"{site.url}/v1/maps/site/label-table").json()
    shown = page.execute_script("return [...document.querySelectorAll('#labels-table tr')]"
                                ".map(r => r.dataset.category)")
    assert shown == [str(row["category"]) for row in table["categories"]]
    category = table["categories"][0]
    label = "storage" if category["label"] != "storage" else "corridor"
    Select(page.find_element("css selector", f"#labels-table select[data-category='{category['category']}']")
           ).select_by_value(label)
    page.find_element("css selector", "#labels-form button[type=submit]").click()
    wait_until(page, "return !document.getElementById('key-dialog').hidden", what="the key prompt")
    assert "write key" in page.find_element("id", "key-reason").text
    page.find_element("id", "key-input").send_keys(write_key + "\n")
    wait_until(page, "return document.getElementById('labels-info').textContent.startsWith('Saved')",
               what="the label table saved")
    assert httpx.get(f"{site.url}/v1/maps/site/label-table").json()["overrides"] == {str(category["category"]): label}
    assert page.execute_script("return sessionStorage.getItem('aisle.apiKey')") == write_key
    assert console_problems(page, allowed=("401 (Unauthorized)",)) == []
    page.execute_script("sessionStorage.clear()")
