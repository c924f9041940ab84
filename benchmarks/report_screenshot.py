"""The gap report as a person sees it: the docs' per-flight example rendered in a browser.

Runs the example of docs/gap.md ("Per flight, on the shared Crazyflie data": a payload flight
of ``mixed/`` and a nominal flight that is not a reference, each judged against six nominal
flights) with ``--report``, then opens the page in headless Chromium at 1400 px wide and
saves what the first screens show as a PNG (the docs' screenshot, ``docs/img/gap_report.png``)::

    nice -n 5 python benchmarks/report_screenshot.py [--data ../shared/data] \\
        [--out docs/img/gap_report.png] [--height 1800] [--keep-html pf.html]

Exit 0 with one ``skipped:`` line when the data folder or a Chromium is absent (``chromium``,
``chromium-browser``, ``google-chrome``; on Debian/Ubuntu ``apt-get install chromium``).
Not a test: it shows; ``tests/test_report_html.py`` checks the page's structure.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: the docs' example: judged flights and references (docs/gap.md, "Run it")
JUDGED = ("mixed/flight_110.csv.gz", "nominal/flight_19.csv.gz")
REFERENCES = tuple(f"nominal/flight_{k:02d}.csv.gz" for k in (0, 4, 8, 12, 16, 18))
BROWSERS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")


def browser() -> str | None:
    """The first headless-capable Chromium on the PATH, or None."""
    return next((path for name in BROWSERS if (path := shutil.which(name))), None)


def render(html: Path, png: Path, *, width: int = 1400, height: int = 1800) -> Path:
    """``html`` as the browser shows it in a ``width`` x ``height`` px window, saved to
    ``png`` (the top of the page: what a reader sees first)."""
    exe = browser()
    if exe is None:
        raise FileNotFoundError("no Chromium on the PATH")
    png.parent.mkdir(parents=True, exist_ok=True)
    subprocess.run([exe, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                    f"--window-size={width},{height}", f"--screenshot={png.resolve()}",
                    html.resolve().as_uri()], check=True, capture_output=True, timeout=120)
    return png


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", default=str(ROOT.parent / "shared" / "data"))
    parser.add_argument("--out", default=str(ROOT / "docs" / "img" / "gap_report.png"))
    parser.add_argument("--height", type=int, default=1800, help="window height (px)")
    parser.add_argument("--keep-html", help="also keep the report at this path")
    args = parser.parse_args(argv)
    data = Path(args.data) / "crazyflie21_brushless"
    if not data.is_dir():
        print(f"skipped: {data} not found")
        return 0
    if browser() is None:
        print("skipped: no Chromium on the PATH (apt-get install chromium)")
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        html = Path(args.keep_html) if args.keep_html else Path(tmp) / "pf.html"
        cmd = [sys.executable, "-m", "quadsim.gap", "--model", "crazyflie21", "--per-flight",
               *(str(data / f) for f in JUDGED), "--reference",
               *(str(data / f) for f in REFERENCES), "--workers", "1", "--quiet",
               "--report", str(html)]
        subprocess.run(cmd, check=True, cwd=ROOT)
        png = render(html, Path(args.out), height=args.height)
    print(f"wrote {png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
