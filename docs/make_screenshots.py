"""Regenerate docs/report.png and docs/live-page.png (needs chromium, chromium-driver and selenium).

    .venv/bin/python docs/make_screenshots.py [REPORT_DIR]

REPORT_DIR: an existing `wallcal run` output (default: runs a quick study into a temporary directory).
"""

import shutil
import sys
import tempfile
import threading
import time
from pathlib import Path

from selenium import webdriver
from selenium.webdriver.chrome.service import Service

import wallcal
from wallcal.web.server import serve
from wallcal.workflow import run_study

DOCS = Path(__file__).resolve().parent
EXAMPLE = DOCS.parent / "src" / "wallcal" / "examples" / "campaign_a" / "study.toml"


def main():
    tmp = Path(tempfile.mkdtemp())
    if len(sys.argv) > 1:
        report = Path(sys.argv[1]) / "index.html"
    else:
        run_study(wallcal.load_study(EXAMPLE), tmp / "report", progress=False)
        report = tmp / "report" / "index.html"
    opts = webdriver.ChromeOptions()
    opts.binary_location = "/usr/bin/chromium"
    for a in (
        "--headless=new",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-background-networking",
        "--window-size=1400,1000",
        "--hide-scrollbars",
    ):
        opts.add_argument(a)
    d = webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=opts)
    try:
        d.get(report.as_uri())
        time.sleep(0.5)
        d.save_screenshot(str(DOCS / "report.png"))
        for f in ("measured.csv", "true_wall.toml", "study.toml"):
            shutil.copy(EXAMPLE.parent / f, tmp / f)
        box = {}
        threading.Thread(
            target=serve,
            args=(tmp / "study.toml",),
            kwargs={"port": 0, "ready": lambda h: box.update(h=h)},
            daemon=True,
        ).start()
        while "h" not in box:
            time.sleep(0.1)
        d.get(box["h"].url)
        while not d.execute_script("return Number(document.body.dataset.version || 0)"):
            time.sleep(0.1)
        d.execute_script(
            "const r = document.getElementById('ctl-3-conductivity'); r.value = 0.0455;"
            "r.dispatchEvent(new Event('input'));"
        )
        time.sleep(0.8)
        d.save_screenshot(str(DOCS / "live-page.png"))
    finally:
        d.quit()
    print("wrote", DOCS / "report.png", DOCS / "live-page.png")


if __name__ == "__main__":
    main()
