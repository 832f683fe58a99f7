#!/usr/bin/env python3
"""The built-in viewer in a real browser (headless Chromium through selenium), against a running
irs-planner server: `python3 tests/browser/viewer_test.py URL SCREENSHOT.png`.

Loads the page, selects the paper's single-user scenario, sets the threshold to -63 dB with the
keyboard, clicks q_I = (-10, 0) and q_F = (10, 0) on the map, and checks that
* the distance shown equals the API's own answer for the same query,
* the path is drawn (the canvas pixels at the path's cells change),
* the browser logged no console error and requested nothing but the server's own origin,
then saves a screenshot. Prints "N passed, 0 failed" and exits 0, or names the failed check.
"""

import pathlib
import sys

from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.by import By
from selenium.webdriver.common.keys import Keys
from selenium.webdriver.support.ui import Select, WebDriverWait

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "support"))
import irs_testkit as kit  # noqa: E402

import chromium  # noqa: E402  (tests/browser/chromium.py, beside this file)

BASE = sys.argv[1].rstrip("/")
SCREENSHOT = sys.argv[2]
Q_I, Q_F = (-10.0, 0.0), (10.0, 0.0)
THRESHOLD = -63.0

CHECKS = kit.Checks()
check = CHECKS.check


def api(method, path, body=None):
    """The JSON answer (a status outside 2xx raises)."""
    return kit.request(BASE, method, path, body, timeout=30, raise_for_status=True).body


driver = chromium.start(1500, 1100)
wait = WebDriverWait(driver, 30)

try:
    driver.get(BASE + "/")
    wait.until(lambda d: d.find_element(By.ID, "scenario").get_attribute("value"))
    scenarios = api("GET", "/v1/scenarios")["scenarios"]
    paper = next(s["id"] for s in scenarios if s["name"] == "paper-single-user")
    Select(driver.find_element(By.ID, "scenario")).select_by_value(paper)
    wait.until(lambda d: "Map " in d.find_element(By.ID, "status").text)
    key = {"scenario_id": paper, "kind": "gain", "phases": "continuous"}
    map_id = api("POST", "/v1/maps", key)["map_id"]
    wait.until(lambda d: d.execute_script("return document.getElementById('download-map').href").endswith(map_id))
    check(True, "the viewer shows the paper map", map_id)

    # The threshold typed like a user would: focus the number box, replace, press Enter.
    box = driver.find_element(By.ID, "threshold")
    box.send_keys(Keys.CONTROL, "a")
    box.send_keys(str(THRESHOLD), Keys.ENTER)
    wait.until(lambda d: d.find_element(By.ID, "threshold-range").get_attribute("value") == str(int(THRESHOLD)))
    coverage = api("GET", f"/v1/maps/{map_id}/coverage?threshold={THRESHOLD}")
    wanted = f"{100 * coverage['coverage']:.1f} % ({coverage['covered_cells']} of"
    try:
        wait.until(lambda d: wanted in d.find_element(By.ID, "coverage").text)
    except Exception:
        pass
    shown = driver.find_element(By.ID, "coverage").text
    check(wanted in shown, "coverage shown is the API's", f"{shown} (API: {wanted}…)")

    query = {"map_id": map_id, "start": list(Q_I), "goal": list(Q_F), "threshold": THRESHOLD}
    expected = api("POST", "/v1/paths", query)
    canvas = driver.find_element(By.ID, "map")
    layout = driver.execute_script(
        "const c = arguments[0]; const r = c.getBoundingClientRect();"
        "return {w: r.width, h: r.height, left: +c.dataset.left, top: +c.dataset.top, cell: +c.dataset.cell};",
        canvas)
    grid = api("GET", f"/v1/maps/{map_id}")["grid"]

    def pixel_of(x, y):
        i = round((x - grid["x_min"]) / grid["resolution_m"])
        j = round((y - grid["y_min"]) / grid["resolution_m"])
        return (layout["left"] + (i + 0.5) * layout["cell"],
                layout["top"] + (grid["ny"] - 1 - j + 0.5) * layout["cell"])

    def canvas_rgb(points):
        return driver.execute_script(
            "const ctx = arguments[0].getContext('2d');"
            "return arguments[1].map(p => Array.from(ctx.getImageData(p[0], p[1], 1, 1).data.slice(0, 3)));",
            canvas, [list(map(int, p)) for p in points])

    inner = [pixel_of(w["x"], w["y"]) for w in expected["waypoints"][2:-2]]
    before = canvas_rgb(inner)
    for point in (Q_I, Q_F):
        px, py = pixel_of(*point)
        # Selenium 4 offsets are from the element's centre.
        ActionChains(driver).move_to_element_with_offset(
            canvas, int(px - layout["w"] / 2), int(py - layout["h"] / 2)).click().perform()
    wait.until(lambda d: d.find_element(By.ID, "distance").get_attribute("data-value"))
    shown = float(driver.find_element(By.ID, "distance").get_attribute("data-value"))
    check(shown == expected["distance_m"], "distance shown equals the API's answer",
          f"viewer {shown} m, API {expected['distance_m']} m")
    distance_text = driver.find_element(By.ID, "distance").text
    check(distance_text == f"{expected['distance_m']:.2f} m", "the distance is printed as text", distance_text)
    rows = driver.find_elements(By.CSS_SELECTOR, "#waypoints tbody tr")
    check(len(rows) == len(expected["waypoints"]), "every waypoint is listed as text", f"{len(rows)} rows")
    after = canvas_rgb(inner)
    changed = sum(b != a for b, a in zip(before, after))
    check(changed >= 0.9 * len(inner), "the path is drawn on its cells", f"{changed} of {len(inner)} changed")

    # Hovering a waypoint shows its details.
    px, py = pixel_of(expected["waypoints"][5]["x"], expected["waypoints"][5]["y"])
    ActionChains(driver).move_to_element_with_offset(
        canvas, int(px - layout["w"] / 2), int(py - layout["h"] / 2)).perform()
    tip = driver.find_element(By.ID, "tooltip")
    wait.until(lambda d: tip.is_displayed())
    check("IRS phases: 60" in tip.text, "hovering a waypoint shows its value and phases", tip.text.replace("\n", " | "))

    # The any-angle route of the same query: what the API answers, shorter than the grid's.
    Select(driver.find_element(By.ID, "path-shape")).select_by_value("any_angle")
    any_angle = api("POST", "/v1/paths", {**query, "path_shape": "any_angle"})
    wait.until(lambda d: float(d.find_element(By.ID, "distance").get_attribute("data-value") or "nan")
               == any_angle["distance_m"])
    shown = float(driver.find_element(By.ID, "distance").get_attribute("data-value"))
    check(shown == any_angle["distance_m"] < expected["distance_m"],
          "an any-angle route is shown, shorter than the grid's",
          f"{shown} m vs {expected['distance_m']} m")
    Select(driver.find_element(By.ID, "path-shape")).select_by_value("grid")
    wait.until(lambda d: float(d.find_element(By.ID, "distance").get_attribute("data-value"))
               == expected["distance_m"])

    driver.save_screenshot(SCREENSHOT)

    # A rate map: built as a job, then the certificate gap can be shown as a layer.
    small = next(s["id"] for s in scenarios if s["name"] == "small-test")
    Select(driver.find_element(By.ID, "scenario")).select_by_value(small)
    Select(driver.find_element(By.ID, "kind")).select_by_value("rate")
    rate_key = {"scenario_id": small, "kind": "rate", "phases": "continuous", "access": "noma"}
    wait.until(lambda d: d.execute_script("return document.querySelector('.unit').textContent") == "bit/s/Hz")
    rate_id = api("POST", "/v1/maps", rate_key)["map_id"]
    check(driver.execute_script("return document.getElementById('download-map').href").endswith(rate_id),
          "the rate map is shown after its job", rate_id)
    gap = driver.find_element(By.ID, "layer-gap")
    check(gap.is_enabled(), "the certificate-gap layer is offered for rate maps")
    pixels = driver.execute_script(
        "const c = arguments[0]; return Array.from(c.getContext('2d').getImageData(0, 0, c.width, c.height).data).join();",
        canvas)
    gap.send_keys(Keys.SPACE)
    wait.until(lambda d: "gap" in d.execute_script("return document.querySelector('input[name=layer]:checked').value"))
    redrawn = driver.execute_script(
        "const c = arguments[0]; return Array.from(c.getContext('2d').getImageData(0, 0, c.width, c.height).data).join();",
        canvas)
    check(pixels != redrawn, "choosing the gap layer (keyboard) redraws the map")

    chromium.check_console_and_origin(driver, BASE, check)
finally:
    driver.quit()

CHECKS.finish()
