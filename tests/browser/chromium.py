"""What the browser suites share: headless Chromium driven through selenium, with the page's
console and network logs kept, and the checks every page of the viewer must pass at the end (no
console error, no request outside the server's origin)."""

import json

from selenium import webdriver
from selenium.webdriver.chrome.service import Service


def start(width, height):
    """Headless Chromium in a window of `width` × `height`, logging the console and the network."""
    options = webdriver.ChromeOptions()
    for flag in ["--headless=new", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-dev-shm-usage", f"--window-size={width},{height}",
                 "--no-first-run", "--disable-sync", "--disable-default-apps", "--hide-scrollbars"]:
        options.add_argument(flag)
    options.binary_location = "/usr/bin/chromium"
    options.set_capability("goog:loggingPrefs", {"browser": "ALL", "performance": "ALL"})
    return webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=options)


def check_console_and_origin(driver, base, check):
    """No console error, and every request the page made went to `base` (or was data:/blob:)."""
    errors = [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]
    check(not errors, "no console errors", json.dumps(errors)[:800])
    urls = []
    for entry in driver.get_log("performance"):
        message = json.loads(entry["message"])["message"]
        if message["method"] == "Network.requestWillBeSent":
            urls.append(message["params"]["request"]["url"])
    foreign = [u for u in urls if not (u.startswith(base + "/") or u.startswith(("data:", "blob:")))]
    check(urls and not foreign, "no request leaves the server's origin",
          f"{len(urls)} requests" + (f", foreign: {foreign[:5]}" if foreign else ""))
