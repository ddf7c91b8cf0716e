"""A real headless Chromium for the tests of pages (Debian's chromium and chromium-driver, which
`make test` installs)."""

from __future__ import annotations

import shutil

CHROME_ARGS = ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
               "--disable-background-networking", "--disable-component-update", "--disable-sync",
               "--disable-dev-shm-usage")


#: No network but this machine: every host other than loopback goes to a proxy that is not there
#: (Chromium reaches loopback directly whatever the proxy), as on a ground station offline.
OFFLINE_ARGS = ("--proxy-server=http://127.0.0.1:9",)


def chromium(offline: bool = False):
    from selenium import webdriver
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    browser, driver = shutil.which("chromium"), shutil.which("chromedriver")
    assert browser and driver, "the map test needs Debian's chromium and chromium-driver: `make test` installs them"
    opts = Options()
    for a in CHROME_ARGS + (OFFLINE_ARGS if offline else ()):
        opts.add_argument(a)
    opts.binary_location = browser
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(service=Service(driver), options=opts)


def page_state(path, script: str):
    """Load a local page in headless Chromium, wait until its images are decoded, and run ``script``
    (a function body returning a value) in it: (that value, the console's errors)."""
    d = chromium()
    try:
        d.get(path.as_uri())
        d.implicitly_wait(2)
        # the page's pictures decoded (an event, not a time): a loaded machine may run the script first
        d.set_script_timeout(60)
        d.execute_async_script(
            "const done = arguments[arguments.length - 1];"
            "Promise.all([...document.images].map(i => i.decode().catch(() => null))).then(() => done(true));")
        value = d.execute_script(script)
        errors = [e for e in d.get_log("browser") if e["level"] in ("SEVERE", "ERROR")]
    finally:
        d.quit()
    return value, errors
