"""report.html and replay.html in headless Chromium, from the file system, offline.

Each page must load with no console error and no request but file:, data: and
blob: ones; the replay's three.js scene must hold the arm's links and, at the end
of the animation, put the tool where the traces do (at the plate). A screenshot of
each page is saved next to it and into the artefact folder (NSDRAKE_TEST_ARTIFACTS,
default test-artifacts/ in the repository).

Needs Debian's chromium and chromium-driver (.ci/run installs them) and selenium
(the test extra); skipped with the reason when either is missing, except under
NSDRAKE_REQUIRE_BROWSER=1 (set by .ci/run), where that is a failure. The driver
and the browser are given explicitly, so selenium never downloads either.
"""

from __future__ import annotations

import io
import json
import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import SHORT_RUN_DURATION

from nsdrake.experiment.traces import Traces

CHROMIUM = os.environ.get("NSDRAKE_CHROMIUM", "/usr/bin/chromium")
CHROMEDRIVER = os.environ.get("NSDRAKE_CHROMEDRIVER", "/usr/bin/chromedriver")
ARTIFACTS = Path(
    os.environ.get("NSDRAKE_TEST_ARTIFACTS", Path(__file__).resolve().parents[2] / "test-artifacts")
)

# The contact-force arrow between the tool sphere and the plate: Drake names the pair by
# geometry (body.geometry) because the tool body carries two collision shapes.
CONTACT_ARROW = "/drake/contact_forces/point/tool.tool_collision+plate"
FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--enable-unsafe-swiftshader",  # software WebGL for the replay, on local files only
    "--host-resolver-rules=MAP * ~NOTFOUND",  # no name resolves: nothing can leave the machine
    "--window-size=1280,800",
]
ALLOWED_SCHEMES = ("file:", "data:", "blob:")


def _missing() -> str:
    """Why the browser test cannot run here, or ""."""
    try:
        import selenium.webdriver  # noqa: F401
    except ImportError:
        return "selenium is not installed: pip install -e '.[test]'"
    if not (os.access(CHROMIUM, os.X_OK) and os.access(CHROMEDRIVER, os.X_OK)):
        return (
            f"no headless browser: {CHROMIUM} or {CHROMEDRIVER} is missing "
            "(Debian: apt-get install chromium chromium-driver; .ci/run installs them)"
        )
    return ""


if _missing():
    if os.environ.get("NSDRAKE_REQUIRE_BROWSER"):  # .ci/run: the test must run, not skip
        pytest.fail(f"NSDRAKE_REQUIRE_BROWSER is set but {_missing()}", pytrace=False)
    pytest.skip(_missing(), allow_module_level=True)
from selenium import webdriver  # noqa: E402
from selenium.webdriver.chrome.service import Service  # noqa: E402
from selenium.webdriver.support.ui import WebDriverWait  # noqa: E402


@pytest.fixture(scope="module")
def browser():
    profile = tempfile.mkdtemp(prefix="nsdrake-chromium-")
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for flag in FLAGS:
        options.add_argument(flag)
    options.add_argument(f"--user-data-dir={profile}")
    options.set_capability("goog:loggingPrefs", {"browser": "ALL", "performance": "ALL"})
    driver = webdriver.Chrome(service=Service(executable_path=CHROMEDRIVER), options=options)
    try:
        driver.execute_cdp_cmd("Network.enable", {})
        driver.execute_cdp_cmd(
            "Network.emulateNetworkConditions",
            {"offline": True, "latency": 0, "downloadThroughput": -1, "uploadThroughput": -1},
        )
        yield driver
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)


def open_page(driver, path: Path) -> None:
    driver.get("about:blank")
    driver.get_log("browser")  # drop what the browser logged before our page
    driver.get_log("performance")
    driver.get(path.resolve().as_uri())
    WebDriverWait(driver, 30).until(lambda d: d.execute_script("return document.readyState") == "complete")


def requested_urls(driver) -> list[str]:
    urls = []
    for entry in driver.get_log("performance"):
        message = json.loads(entry["message"])["message"]
        if message["method"] == "Network.requestWillBeSent":
            urls.append(message["params"]["request"]["url"])
    return urls


def severe_messages(driver) -> list[str]:
    return [e["message"] for e in driver.get_log("browser") if e["level"] == "SEVERE"]


def screenshot(driver, path: Path) -> bytes:
    png = driver.get_screenshot_as_png()
    path.write_bytes(png)
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    shutil.copy(path, ARTIFACTS / path.name)
    return png


def blue_pixels(png: bytes) -> int:
    """Pixels of the links' blue (rgba 0.25 0.45 0.8 in arm4.urdf, shaded): the arm is drawn."""
    import matplotlib.image

    rgb = matplotlib.image.imread(io.BytesIO(png), format="png")[..., :3]
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    return int(np.count_nonzero((b > r + 0.25) & (b > g + 0.1)))


_SCENE = """
const node = (path) => path.split('/').filter(Boolean).reduce(
    (n, name) => (n && n.children[name]) || null, viewer.scene_tree);
const meshes = (n) => { let k = 0; n.object.traverse(o => { if (o.isMesh) k += 1; }); return k; };
return arguments[0].map(p => { const n = node(p); return n === null ? null :
    {meshes: meshes(n), position: n.object.position.toArray(), visible: n.object.visible}; });
"""


def test_replay_loads_offline_and_shows_the_arm_at_the_plate(browser, short_run):
    out, _ = short_run
    open_page(browser, out / "replay.html")
    # The scene arrives as inlined messages handled after load; the animation last.
    WebDriverWait(browser, 60).until(lambda d: d.execute_script("return viewer.animator.duration > 0"))
    duration = browser.execute_script("return viewer.animator.duration")
    browser.execute_script("viewer.animator.pause(); viewer.animator.seek(arguments[0]);", duration)
    time.sleep(0.5)  # a few animation frames to draw the seeked pose

    links = [f"/drake/visualizer/arm4/{name}" for name in ("link1", "link2", "link3", "link4", "tool")]
    paths = [*links, "/drake/visualizer/plate/plate", CONTACT_ARROW]
    nodes = dict(zip(paths, browser.execute_script(_SCENE, paths), strict=True))
    missing = [p for p, n in nodes.items() if n is None or n["meshes"] == 0]
    assert missing == [], f"not in the three.js scene: {missing}"
    # At the end of the run the tool presses on the plate, where the traces put it …
    traces = Traces.read_csv(out / "traces.csv")
    tool = nodes["/drake/visualizer/arm4/tool"]["position"]
    assert abs(duration - SHORT_RUN_DURATION) < 0.05
    k = int(np.searchsorted(traces["t"], duration - 1e-9))
    assert np.allclose(tool[:2], [traces["x"][k], traces["y"][k]], atol=1e-6)
    assert traces["f_n"][k] > 5.0
    # … and the contact force is drawn.
    assert nodes[CONTACT_ARROW]["visible"]

    png = screenshot(browser, out / "replay.png")
    assert blue_pixels(png) > 500, "the arm's links are not on the screenshot"
    assert severe_messages(browser) == []
    assert [u for u in requested_urls(browser) if not u.startswith(ALLOWED_SCHEMES)] == []


def test_replay_opens_at_the_start_with_play_in_view(browser, short_run):
    """replay.html opens paused at t = 0 (the tool where the traces' first row puts it, not
    at the plate), its play button visible in the window and Meshcat's animation controls
    open; the button plays the recording. Catches the page opening on the last frame with
    play folded under Open Controls."""
    out, _ = short_run
    open_page(browser, out / "replay.html")
    WebDriverWait(browser, 60).until(lambda d: d.execute_script("return viewer.animator.duration > 0"))
    time.sleep(1.0)  # the page's own start-up: the animation loaded, then set to t = 0
    state = browser.execute_script(
        "const a = viewer.animator; return {playing: a.playing, gui_closed: viewer.gui.closed,"
        " time: a.actions.reduce((t, x) => Math.max(t, x.time), 0)};"
    )
    assert state == {"playing": False, "gui_closed": False, "time": 0}
    tool = browser.execute_script(_SCENE, ["/drake/visualizer/arm4/tool"])[0]["position"]
    traces = Traces.read_csv(out / "traces.csv")
    assert np.allclose(tool[:2], [traces["x"][0], traces["y"][0]], atol=1e-6)
    assert traces["f_n"][0] < 1.0  # the start: not yet at the plate
    button = browser.find_element("id", "nsdrake-play")
    rect = browser.execute_script("return arguments[0].getBoundingClientRect().toJSON()", button)
    width, height = browser.execute_script("return [window.innerWidth, window.innerHeight]")
    assert button.is_displayed() and 0 <= rect["left"] and rect["right"] <= width and rect["bottom"] <= height
    assert "play" in button.text
    screenshot(browser, out / "replay_start.png")
    # The largest time the animation shows once played (a slow software renderer may reach
    # the end in one frame, where Meshcat rewinds it: so the largest, not the current).
    browser.execute_script(
        "const a = viewer.animator; window.shownMax = 0; const show = a.display_progress.bind(a);"
        "a.display_progress = (t) => { window.shownMax = Math.max(window.shownMax, t); show(t); };"
    )
    button.click()
    WebDriverWait(browser, 30).until(lambda d: d.execute_script("return window.shownMax > 0"))
    assert severe_messages(browser) == []


def test_report_loads_offline_with_its_plots_and_diagram(browser, short_run):
    out, result = short_run
    open_page(browser, out / "report.html")
    rows = browser.execute_script("return document.querySelectorAll('tr[data-metric]').length")
    assert rows == len(result.metrics)
    images = browser.execute_script(
        "return Array.from(document.images).map(i => [i.complete, i.naturalWidth, i.naturalHeight]);"
    )
    assert images and all(ok and w > 100 and h > 100 for ok, w, h in images)
    if (out / "diagram.svg").exists():
        assert browser.execute_script("return document.querySelectorAll('.diagram svg g.node').length") >= 20
    replay = browser.execute_script("return document.getElementById('replay-link').href")
    assert replay == (out / "replay.html").resolve().as_uri()
    height = browser.execute_script("return document.documentElement.scrollHeight")
    browser.set_window_size(1280, min(max(height, 800), 6000))
    screenshot(browser, out / "report.png")
    browser.set_window_size(1280, 800)
    assert severe_messages(browser) == []
    assert [u for u in requested_urls(browser) if not u.startswith(ALLOWED_SCHEMES)] == []
