"""Look at the built documentation in headless Chromium: the front page, one example, the API page.

    python docs/screenshots.py docs/_build/html [--out docs/_build/screenshots]

For each page, Chromium (Debian's ``chromium``) writes a screenshot and the page's DOM after its
scripts ran (``--dump-dom``). The screenshot must not be blank (the standard deviation of its grey
levels at least :data:`MIN_STD`: a white or single-colour page has ~0) and the DOM's text must contain
the page's expected headings. Exits 1 naming the page and what is wrong, 2 when Chromium is missing.
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import tempfile
from html import unescape
from pathlib import Path

#: Pages to look at and headings each must show (relative to the build folder).
PAGES = {
    "index.html": ("netlistdyn", "User guide", "Netlist language", "API reference"),
    "examples/mechanical.html": (
        "Mechanical systems of the lecture notes",
        "Double inverted pendulum on a cart",
    ),
    "api/index.html": ("API reference", "Public API", "netlistdyn.compile", "netlistdyn.StateSpaceModel"),
}
#: Least standard deviation of a screenshot's grey levels (0–255) for it to count as drawn.
MIN_STD = 10.0
#: Chromium is given this long per call before the page counts as hung.
TIMEOUT_S = 120

FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--hide-scrollbars",
    "--window-size=1280,1000",
)


def _chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        found = shutil.which(name)
        if found:
            return found
    return None


def _run(browser: str, profile: Path, extra: list[str], url: str) -> subprocess.CompletedProcess[str]:
    command = [browser, *FLAGS, f"--user-data-dir={profile}", *extra, url]
    return subprocess.run(command, capture_output=True, text=True, timeout=TIMEOUT_S, check=False)


def grey_std(png: Path) -> float:
    """Standard deviation of the grey levels of an image."""
    from PIL import Image, ImageStat

    with Image.open(png) as image:
        return float(ImageStat.Stat(image.convert("L")).stddev[0])


def dom_text(dom: str) -> str:
    """The visible text of a DOM dump, whitespace collapsed."""
    dom = re.sub(r"<(script|style)\b.*?</\1>", " ", dom, flags=re.S | re.I)
    return re.sub(r"\s+", " ", unescape(re.sub(r"<[^>]+>", " ", dom)))


def check(root: Path, out: Path) -> list[str]:
    """Screenshot and DOM-check every page of :data:`PAGES`; the problems found."""
    browser = _chromium()
    if browser is None:
        raise FileNotFoundError("chromium is not installed (apt-get install -y chromium)")
    out.mkdir(parents=True, exist_ok=True)
    problems = []
    with tempfile.TemporaryDirectory(prefix="netlistdyn-chromium-") as tmp:
        profile = Path(tmp)
        for page, headings in PAGES.items():
            url = (root / page).resolve().as_uri()
            png = out / (page.replace("/", "_").removesuffix(".html") + ".png")
            png.unlink(missing_ok=True)
            shot = _run(browser, profile, [f"--screenshot={png}"], url)
            if not png.exists():
                reason = shot.stderr.strip()[-300:]
                problems.append(f"{page}: no screenshot (exit {shot.returncode}): {reason}")
                continue
            std = grey_std(png)
            if std < MIN_STD:
                problems.append(f"{page}: the screenshot is blank (grey-level std {std:.1f} < {MIN_STD})")
            dump = _run(browser, profile, ["--dump-dom"], url)
            text = dom_text(dump.stdout)
            missing = [h for h in headings if h not in text]
            if missing:
                problems.append(f"{page}: the page does not show {missing}")
            print(f"{page}: {png} (grey-level std {std:.1f}); {len(text)} characters of text", flush=True)
    return problems


def main() -> int:
    """Check the build folder given on the command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("root", nargs="?", default="docs/_build/html", type=Path)
    parser.add_argument("--out", type=Path, help="folder of the PNGs (default: ROOT/../screenshots)")
    args = parser.parse_args()
    out = args.out or args.root.parent / "screenshots"
    try:
        problems = check(args.root, out)
    except FileNotFoundError as error:
        print(f"screenshots: {error}", file=sys.stderr)
        return 2
    for problem in problems:
        print(f"screenshots: {problem}", file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
