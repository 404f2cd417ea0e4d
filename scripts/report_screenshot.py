"""Writes the picture of a run's report that docs/command_line.md ("Watching a run") shows.

    python scripts/report_screenshot.py --run

runs ``nsdrake run fig3 --out runs/fig3 --no-replay --overwrite`` first (the report names
its folder, so the folder has an ordinary name), then opens runs/fig3/report.html in
headless Chromium (Debian's chromium and chromium-driver, as
tests/reporting/test_browser.py drives them; offline, nothing can leave the machine) and
saves the top of the page, the verdict, the controller, its loops and the first metrics,
to docs/_static/report_fig3.png. Without ``--run`` it pictures the folder given (default
runs/fig3) as it is. It refuses, in one line, a report whose controller and loops are not
above its metrics or which names the folder's absolute path.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM, CHROMEDRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"
WIDTH, HEIGHT = 1180, 1500  # [px] the window: the box, the loops and the first metrics


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "folder", type=Path, nargs="?", default=Path("runs/fig3"), help="a folder nsdrake run wrote"
    )
    parser.add_argument("png", type=Path, nargs="?", default=ROOT / "docs" / "_static" / "report_fig3.png")
    parser.add_argument("--run", action="store_true", help="run fig3 into the folder first")
    args = parser.parse_args()
    if args.run:
        command = [sys.executable, "-m", "nsdrake", "run", "fig3", "--out", str(args.folder)]
        if subprocess.run([*command, "--no-replay", "--overwrite"]).returncode not in (0, 1):
            print(f"'{' '.join(command)}' failed: no picture taken")
            return 1
    report = args.folder / "report.html"
    if not report.is_file():
        print(f"{report}: no report here; run 'nsdrake run fig3 --out {args.folder}' first (or pass --run)")
        return 2
    text = report.read_text()
    places = [text.find(f'id="{part}"') for part in ("controller", "loops", "metrics")]
    if -1 in places or places != sorted(places):
        print(f"{report}: the controller and its loops are not above the metrics: not pictured")
        return 1
    if str(args.folder.resolve()) in text:
        print(f"{report}: names its folder's absolute path: not pictured")
        return 1
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
