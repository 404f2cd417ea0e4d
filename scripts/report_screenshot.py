"""Writes the picture of a run's report that docs/command_line.md ("Watching a run") shows.

    nsdrake run fig3 --out runs/fig3 --no-replay
    python scripts/report_screenshot.py runs/fig3 docs/_static/report_fig3.png

Opens RUN/report.html in headless Chromium (Debian's chromium and chromium-driver, as
tests/reporting/test_browser.py drives them; offline, nothing can leave the machine) and
saves the top of the page: the verdict, the controller, its loops and the first metrics.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

CHROMIUM, CHROMEDRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"
WIDTH, HEIGHT = 1180, 1500  # [px] the window: the box, the loops and the first metrics


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path, help="a folder nsdrake run wrote (with report.html)")
    parser.add_argument("png", type=Path, help="the picture to write")
    args = parser.parse_args()
    report = args.run / "report.html"
    if not report.is_file():
        print(f"{report}: no report here; run 'nsdrake run fig3 --out {args.run}' first")
        return 2
    for program in (CHROMIUM, CHROMEDRIVER):
        if not Path(program).exists():
            print(f"{program} is missing (Debian: apt-get install chromium chromium-driver)")
            return 2
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    profile = tempfile.mkdtemp(prefix="nsdrake-screenshot-")
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for flag in ("--headless", "--no-sandbox", "--disable-gpu", "--host-resolver-rules=MAP * ~NOTFOUND"):
        options.add_argument(flag)
    options.add_argument(f"--window-size={WIDTH},{HEIGHT}")
    options.add_argument(f"--user-data-dir={profile}")
    driver = webdriver.Chrome(service=Service(executable_path=CHROMEDRIVER), options=options)
    try:
        driver.get(report.resolve().as_uri())
        args.png.parent.mkdir(parents=True, exist_ok=True)
        driver.save_screenshot(str(args.png))
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)
    print(f"wrote {args.png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
