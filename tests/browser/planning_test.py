#!/usr/bin/env python3
"""The viewer as a planning tool, in headless Chromium through selenium, against a running
irs-planner server: `python3 tests/browser/planning_test.py URL ARTIFACT_DIR`.

What a site planner or a robotics engineer does, each checked against the API's own answers:
* layout at 1280 × 800 (paper floor and warehouse): the whole map, the threshold and the path
  result in view, nothing scrolls; zoom by button, wheel and keyboard;
* a route chosen with the keyboard only; "largest feasible"; a threshold in dBm; bad input
  answered next to its field;
* an AP and an IRS dragged by pointer events (the IRS lands on a wall, facing into the room),
  an AP added and removed, the serving-AP layer;
* a placement ranked and its best position applied; the difference against the map without
  IRS; the old map marked stale while a new one builds;
* the warehouse's own ROS map (map.yaml + map.pgm) imported through the file input;
* a phone's width (390 × 844): the map first, no sideways scrolling, a route by two taps;
* no console error, no request outside the server's origin.
Screenshots go to ARTIFACT_DIR for people to look at. Prints "N passed, 0 failed" and exits 0,
or names the failed checks.
"""

import base64
import json
import pathlib
import sys

from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.actions.wheel_input import ScrollOrigin
from selenium.webdriver.common.by import By
from selenium.webdriver.common.keys import Keys
from selenium.webdriver.support.ui import Select, WebDriverWait

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "support"))
import irs_testkit as kit  # noqa: E402

import chromium  # noqa: E402  (tests/browser/chromium.py, beside this file)

BASE = sys.argv[1].rstrip("/")
ARTIFACTS = pathlib.Path(sys.argv[2])
ARTIFACTS.mkdir(parents=True, exist_ok=True)
ROOT = pathlib.Path(__file__).resolve().parents[2]

CHECKS = kit.Checks()
check = CHECKS.check


def api(method, path, body=None):
    """The JSON answer (a status outside 2xx raises)."""
    return kit.request(BASE, method, path, body, timeout=60, raise_for_status=True).body


driver = chromium.start(1280, 800)
wait = WebDriverWait(driver, 60)
js = driver.execute_script


def by_id(name):
    return driver.find_element(By.ID, name)


def status_text():
    return by_id("status").text


def canvas_layout():
    return js("const c = document.getElementById('map'); const r = c.getBoundingClientRect();"
              "return {x: r.left, y: r.top, w: r.width, h: r.height, left: +c.dataset.left,"
              " top: +c.dataset.top, cell: +c.dataset.cell, layer: c.dataset.layer,"
              " stale: c.dataset.stale, edit_ms: c.dataset.editMs};")


def shown_map():
    """The map the viewer shows (its id from the download link) and its body."""
    href = js("return document.getElementById('download-map').getAttribute('href')")
    map_id = href.split("/v1/maps/")[1].split("?")[0]
    return map_id, api("GET", f"/v1/maps/{map_id}")


def pixel_of(grid, layout, x, y):
    """The canvas pixel (from the canvas's top-left) of the cell centre nearest (x, y)."""
    i = round((x - grid["x_min"]) / grid["resolution_m"])
    j = round((y - grid["y_min"]) / grid["resolution_m"])
    return (layout["left"] + (i + 0.5) * layout["cell"],
            layout["top"] + (grid["ny"] - 1 - j + 0.5) * layout["cell"])


def at_pixel(px, py):
    """An action chain placed at a canvas pixel (selenium's offsets are from the centre)."""
    layout = canvas_layout()
    return ActionChains(driver).move_to_element_with_offset(
        by_id("map"), int(px - layout["w"] / 2), int(py - layout["h"] / 2))


def click_at(grid, x, y):
    at_pixel(*pixel_of(grid, canvas_layout(), x, y)).click().perform()


def drag(grid, src, dst):
    layout = canvas_layout()
    (sx, sy), (dx, dy) = pixel_of(grid, layout, *src), pixel_of(grid, layout, *dst)
    chain = at_pixel(sx, sy).click_and_hold()
    for k in range(1, 5):
        chain = chain.move_by_offset(int((dx - sx) / 4), int((dy - sy) / 4))
    chain.release().perform()


def choose_scenario(name=None, scenario_id=None):
    if scenario_id is None:
        scenario_id = next(s["id"] for s in api("GET", "/v1/scenarios?limit=1000")["scenarios"]
                           if s["name"] == name)
    Select(by_id("scenario")).select_by_value(scenario_id)
    wait.until(lambda d: shown_map()[1]["key"]["scenario_id"] == scenario_id
               and canvas_layout()["stale"] == "0")
    return scenario_id


def current_scenario():
    scenario_id = by_id("scenario").get_attribute("value")
    return scenario_id, api("GET", f"/v1/scenarios/{scenario_id}")["scenario"]


def wait_status(fragment):
    wait.until(lambda d: fragment in status_text() or "error" in by_id("status").get_attribute("class"))
    check(fragment in status_text(), f"status says {fragment!r}", status_text())


def in_view(element_id):
    r = js(f"const r = document.getElementById('{element_id}').getBoundingClientRect();"
           "return [r.left, r.top, r.right, r.bottom, innerWidth, innerHeight];")
    return r[0] >= 0 and r[1] >= 0 and r[2] <= r[4] + 0.5 and r[3] <= r[5] + 0.5, r


def layout_holds(floor):
    """At this window size: the whole map drawn inside the canvas, the canvas and the controls
    that matter in view, nothing to scroll."""
    _, body = shown_map()
    g = body["grid"]
    L = canvas_layout()
    drawn = (L["left"] >= 0 and L["top"] >= 0 and L["left"] + g["nx"] * L["cell"] <= L["w"] + 0.5
             and L["top"] + g["ny"] * L["cell"] <= L["h"] + 0.5)
    check(drawn, f"{floor}: the whole map is drawn in its panel",
          f"{g['nx']}×{g['ny']} cells of {L['cell']:.2f} px from ({L['left']:.0f}, {L['top']:.0f}) in {L['w']}×{L['h']}")
    for element in ["map", "threshold", "largest", "distance", "feasible"]:
        ok, rect = in_view(element)
        check(ok, f"{floor}: #{element} is in view without scrolling", rect)
    sizes = js("return [document.documentElement.scrollWidth, document.documentElement.scrollHeight, innerWidth, innerHeight];")
    check(sizes[0] <= sizes[2] and sizes[1] <= sizes[3], f"{floor}: the page does not scroll", sizes)


def viewport(width, height, mobile=False):
    """The page's viewport exactly (a headless window's size includes no browser chrome, but
    its viewport is not the window's size either)."""
    driver.execute_cdp_cmd("Emulation.setDeviceMetricsOverride", {
        "width": width, "height": height, "deviceScaleFactor": 1, "mobile": mobile})


def register_warehouse():
    """The warehouse of scenarios/warehouse with its ROS map inline (as an API client sends it)."""
    folder = ROOT / "scenarios/warehouse"
    doc = json.loads((folder / "warehouse.json").read_text())
    meta = {}
    for line in (folder / "map.yaml").read_text().splitlines():
        key, value = (part.strip() for part in line.split(":", 1))
        meta[key] = json.loads(value) if key != "image" and key != "mode" else value
    doc["floor_plan"] = {"image": base64.b64encode((folder / meta.pop("image")).read_bytes()).decode(), **meta}
    doc.pop("route_graph", None)
    return api("POST", "/v1/scenarios", doc)["id"]


try:
    viewport(1280, 800)
    warehouse = register_warehouse()
    driver.get(BASE + "/")
    wait.until(lambda d: "Map " in status_text())
    paper = choose_scenario("paper-single-user")
    map_id, body = shown_map()
    grid = body["grid"]
    print(f"viewport {js('return [innerWidth, innerHeight]')}")

    # ---- layout at 1280 × 800, paper floor and warehouse
    layout_holds("paper floor")
    choose_scenario(scenario_id=warehouse)
    layout_holds("warehouse")
    driver.save_screenshot(str(ARTIFACTS / "desktop-warehouse.png"))
    choose_scenario(scenario_id=paper)

    # ---- zoom: buttons, wheel, keyboard
    fit = canvas_layout()["cell"]
    by_id("zoom-in").click()
    wait.until(lambda d: canvas_layout()["cell"] > fit * 1.2)
    check(abs(canvas_layout()["cell"] / fit - 1.25) < 1e-6, "+ zooms in by 1.25", canvas_layout()["cell"] / fit)
    ActionChains(driver).scroll_from_origin(ScrollOrigin.from_element(by_id("map")), 0, -120).perform()
    wait.until(lambda d: canvas_layout()["cell"] > fit * 1.5)
    check(True, "the wheel zooms in", canvas_layout()["cell"] / fit)
    by_id("map").send_keys(Keys.SHIFT, Keys.ARROW_LEFT)
    by_id("map").send_keys("0")
    wait.until(lambda d: abs(canvas_layout()["cell"] - fit) < 1e-9)
    check(True, "0 on the map fits it again")

    # ---- a threshold typed, then bad input answered next to its field
    box = by_id("threshold")
    box.send_keys(Keys.CONTROL, "a")
    box.send_keys("-63", Keys.ENTER)
    wait.until(lambda d: by_id("threshold-range").get_attribute("value") == "-63")
    box.send_keys(Keys.CONTROL, "a")
    box.send_keys(Keys.BACKSPACE, Keys.ENTER)
    wait.until(lambda d: by_id("threshold-error").text)
    check(by_id("threshold-error").is_displayed() and by_id("threshold-range").get_attribute("value") == "-63",
          "an emptied threshold is refused next to it, not read as 0", by_id("threshold-error").text)
    box.send_keys("-63", Keys.ENTER)
    wait.until(lambda d: not by_id("threshold-error").text)
    by_id("start").send_keys("ten, zero")
    by_id("goal").send_keys("10,0")
    by_id("plan").click()
    wait.until(lambda d: by_id("start-error").text)
    check("x,y" in by_id("start-error").text and by_id("start").get_attribute("aria-invalid") == "true",
          "a malformed point is named next to its field", by_id("start-error").text)
    by_id("clear").click()

    # ---- a route with the keyboard only: the cursor from the centre cell, Enter twice
    canvas = by_id("map")
    js("arguments[0].focus()", canvas)
    cx = grid["nx"] // 2
    keys = [Keys.ARROW_LEFT] * cx + [Keys.ENTER] + [Keys.ARROW_RIGHT] * (grid["nx"] - 1) + [Keys.ENTER]
    ActionChains(driver).send_keys(*keys).perform()
    wait.until(lambda d: by_id("distance").get_attribute("data-value"))
    start = [grid["x_min"], grid["y_min"] + (grid["ny"] // 2) * grid["resolution_m"]]
    goal = [grid["x_min"] + (grid["nx"] - 1) * grid["resolution_m"], start[1]]
    expected = api("POST", "/v1/paths", {"map_id": map_id, "start": start, "goal": goal, "threshold": -63})
    shown = float(by_id("distance").get_attribute("data-value"))
    check(shown == expected["distance_m"], "a route set with the keyboard is the API's",
          f"{shown} m vs {expected['distance_m']} m from {start} to {goal}")

    # ---- largest feasible
    by_id("largest").click()
    widest = api("POST", "/v1/paths", {"map_id": map_id, "start": start, "goal": goal, "threshold": "max"})
    wait.until(lambda d: abs(float(by_id("threshold").get_attribute("value") or "nan")
                             - widest["max_feasible_threshold"]) < 1e-9)
    check(True, "largest feasible sets γ to the API's max_feasible_threshold", widest["max_feasible_threshold"])
    check(by_id("feasible").text == "yes", "the route at the largest γ is feasible", by_id("feasible").text)
    box.send_keys(Keys.CONTROL, "a")
    box.send_keys("-63", Keys.ENTER)

    # ---- the threshold in dBm
    Select(by_id("unit")).select_by_value("dbm")
    wait.until(lambda d: js("return document.querySelector('.unit').textContent") == "dBm")
    t = float(by_id("threshold").get_attribute("value"))
    coverage = api("GET", f"/v1/maps/{map_id}/coverage?threshold={t}&unit=dbm")
    wanted = f"{100 * coverage['coverage']:.1f} % ({coverage['covered_cells']} of"
    wait.until(lambda d: wanted in by_id("coverage").text)
    check(True, "coverage in dBm is the API's", f"{t} dBm: {by_id('coverage').text}")
    Select(by_id("unit")).select_by_value("")
    wait.until(lambda d: js("return document.querySelector('.unit').textContent") == "dB")
    box.send_keys(Keys.CONTROL, "a")
    box.send_keys("-63", Keys.ENTER)

    # ---- devices dragged with the pointer
    _, doc = current_scenario()
    ap = doc["ap"]["position"]
    drag(grid, ap[:2], (8.0, 8.0))
    wait_status("AP 0 moved")
    moved_id, moved = current_scenario()
    check(moved["ap"]["position"] == [8.0, 8.0, ap[2]], "the dragged AP is where it was dropped",
          moved["ap"]["position"])
    check(shown_map()[1]["key"]["scenario_id"] == moved_id, "the map is rebuilt for the edited scenario")
    print(f"drop to picture: {canvas_layout()['edit_ms']} ms (debug build)")
    irs = moved["irs"]["center"]
    drag(grid, irs[:2], (9.5, 3.0))
    wait_status("IRS 0 moved")
    _, moved = current_scenario()
    centre, normal = moved["irs"]["center"], moved["irs"]["normal"]
    check(centre[0] == 10.0 and abs(centre[1] - 3.0) <= 0.5 and normal == [-1.0, 0.0, 0.0],
          "the dragged IRS snaps to the east wall, facing into the room", f"{centre} facing {normal}")
    driver.save_screenshot(str(ARTIFACTS / "editing.png"))

    # ---- an AP added, the serving-AP layer, the AP removed again
    by_id("add-ap").click()
    click_at(grid, -8.0, -8.0)
    wait_status("AP added")
    _, two = current_scenario()
    check(len(two.get("aps", [])) == 2 and two["aps"][1]["position"][:2] == [-8.0, -8.0],
          "an added AP is where the map was clicked", two.get("aps"))
    wait.until(lambda d: by_id("layer-serving").is_enabled())
    by_id("layer-serving").click()
    wait.until(lambda d: canvas_layout()["layer"] == "serving")
    served = api("GET", f"/v1/maps/{shown_map()[0]}")["serving_ap"]
    # One cell of each AP's area, away from every marker: drawn in that AP's colour.
    palette = {0: [31, 119, 180], 1: [255, 127, 14]}
    layout = canvas_layout()
    marks = [p["position"][:2] for p in two["aps"]] + [two["irs"]["center"][:2]]
    drawn = {}
    for i, row in enumerate(served):
        for j, ap in enumerate(row):
            x, y = grid["x_min"] + i * grid["resolution_m"], grid["y_min"] + j * grid["resolution_m"]
            if ap is None or ap in drawn or min(abs(x - a) + abs(y - b) for a, b in marks) < 3:
                continue
            px, py = pixel_of(grid, layout, x, y)
            drawn[ap] = js("return Array.from(arguments[0].getContext('2d')"
                           ".getImageData(arguments[1], arguments[2], 1, 1).data.slice(0, 3));",
                           by_id("map"), int(px), int(py))
    check(drawn == palette, "the serving-AP layer draws each AP's cells in its colour", drawn)
    click_at(grid, -8.0, -8.0)
    wait.until(lambda d: by_id("remove").is_enabled())
    by_id("map").send_keys(Keys.DELETE)
    wait_status("AP 1 removed")
    _, one = current_scenario()
    check("ap" in one and "aps" not in one, "Delete removes the selected AP", list(one))
    wait.until(lambda d: canvas_layout()["layer"] == "value")

    # ---- a placement ranked on the map, the best applied
    Select(by_id("place-objective")).select_by_value("coverage")
    step = by_id("place-step")
    step.send_keys(Keys.CONTROL, "a")
    step.send_keys("4")
    placed_on, _ = current_scenario()
    by_id("place").click()
    wait.until(lambda d: d.find_elements(By.CSS_SELECTOR, "#candidates li"))
    room = one["room"]
    corners = [[room["x_min"], room["y_min"]], [room["x_max"], room["y_min"]],
               [room["x_max"], room["y_max"]], [room["x_min"], room["y_max"]]]
    ranking = api("POST", "/v1/placements", {
        "scenario_id": placed_on, "what": "irs",
        "candidates": {"walls": [{"from": corners[k], "to": corners[(k + 1) % 4]} for k in range(4)], "step_m": 4},
        "objective": {"kind": "coverage", "threshold": -63}})
    best = ranking["candidates"][0]
    first = driver.find_elements(By.CSS_SELECTOR, "#candidates li")[0]
    check(f"({best['center'][0]:g}, {best['center'][1]:g})" in first.text, "the ranking shown is the API's",
          f"{first.text} vs {best['center']}")
    driver.save_screenshot(str(ARTIFACTS / "placement.png"))
    first.find_element(By.TAG_NAME, "button").click()
    wait_status("Candidate 1 applied")
    _, applied = current_scenario()
    check(applied["irs"]["center"] == best["center"] and applied["irs"]["normal"] == best["normal"],
          "applying the best candidate moves the IRS there", applied["irs"])

    # ---- the difference against the map without IRS
    Select(by_id("compare")).select_by_value("no-irs")
    wait.until(lambda d: canvas_layout()["layer"] == "difference")
    check(by_id("layer-difference").is_selected(), "the difference layer is shown and chosen")
    driver.save_screenshot(str(ARTIFACTS / "compare.png"))
    Select(by_id("compare")).select_by_value("")
    wait.until(lambda d: canvas_layout()["layer"] == "value")

    # ---- stale while building: a rate map no one asked for before is a job; while it runs
    # the old map stays on screen, marked stale, and the mark goes with the new map.
    choose_scenario("small-test")
    old_pixels = js("const c = document.getElementById('map');"
                    "return Array.from(c.getContext('2d').getImageData(0, 0, c.width, c.height).data).join();")
    Select(by_id("phases")).select_by_value("1")
    Select(by_id("kind")).select_by_value("rate")
    WebDriverWait(driver, 60, poll_frequency=0.02).until(
        lambda d: by_id("job").is_displayed() or js("return document.querySelector('.unit').textContent") == "bit/s/Hz")
    building = by_id("job").is_displayed()
    stale = canvas_layout()["stale"]
    veiled = js("const c = document.getElementById('map');"
                "return Array.from(c.getContext('2d').getImageData(0, 0, c.width, c.height).data).join();")
    check(building and stale == "1" and veiled != old_pixels,
          "while the rate map builds, the old map is veiled and marked stale",
          f"job shown {building}, stale {stale}")
    wait.until(lambda d: js("return document.querySelector('.unit').textContent") == "bit/s/Hz")
    check(canvas_layout()["stale"] == "0", "the new map is not stale")
    Select(by_id("kind")).select_by_value("gain")
    Select(by_id("phases")).select_by_value("continuous")
    wait.until(lambda d: js("return document.querySelector('.unit').textContent") == "dB")

    # ---- the warehouse's ROS map imported through the file input
    choose_scenario(scenario_id=paper)
    js("document.getElementById('import').open = true")
    files = [str(ROOT / "scenarios/warehouse/map.yaml"), str(ROOT / "scenarios/warehouse/map.pgm")]
    by_id("ros-files").send_keys("\n".join(files))
    by_id("ros-import").click()
    wait_status("imported")
    _, imported = current_scenario()
    check(imported["room"]["x_min"] == -30 and imported["room"]["x_max"] == 30
          and imported["room"]["y_min"] == -20 and imported["room"]["y_max"] == 20
          and "floor_plan" in imported, "the imported floor is the ROS map's extent",
          imported["room"])
    _, body = shown_map()
    check(body["stats"]["occupied_cells"] > 0, "its racks and walls are occupied cells",
          body["stats"]["occupied_cells"])
    driver.save_screenshot(str(ARTIFACTS / "imported.png"))

    # ---- a phone's width: the map first, no sideways scrolling, a route by two taps
    viewport(390, 844, mobile=True)
    driver.get(BASE + "/")
    wait.until(lambda d: "Map " in status_text())
    choose_scenario(scenario_id=paper)
    sizes = js("return [document.documentElement.scrollWidth, innerWidth];")
    check(sizes[0] <= sizes[1], "a phone's width does not scroll sideways", sizes)
    order = js("return [document.getElementById('map').getBoundingClientRect().top,"
               " document.getElementById('controls').getBoundingClientRect().top];")
    check(order[0] < order[1], "the map comes before the controls", order)
    _, body = shown_map()
    g = body["grid"]
    box = by_id("threshold")
    box.send_keys(Keys.CONTROL, "a")
    box.send_keys("-63", Keys.ENTER)
    wait.until(lambda d: by_id("threshold-range").get_attribute("value") == "-63")
    click_at(g, -10.0, 0.0)
    click_at(g, 10.0, 0.0)
    wait.until(lambda d: by_id("distance").get_attribute("data-value"))
    check(float(by_id("distance").get_attribute("data-value")) == expected["distance_m"],
          "two taps plan the route the API answers", by_id("distance").text)
    driver.save_screenshot(str(ARTIFACTS / "phone.png"))

    chromium.check_console_and_origin(driver, BASE, check)
except Exception as error:  # noqa: BLE001 - a failed step is a failed check, with the page's state
    driver.save_screenshot(str(ARTIFACTS / "failure.png"))
    check(False, "the walk-through ran to its end",
          f"{type(error).__name__}: {error}; status: {status_text()!r}")
finally:
    driver.quit()

CHECKS.finish()
