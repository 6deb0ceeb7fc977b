"""Render an encounter .rrd in the Rerun web viewer headless and save a PNG (the README screenshot).

    python docs/make_screenshot.py ENCOUNTER.rrd OUT.png [--wait 20] [--width 1600 --height 900]
    python docs/make_screenshot.py --readme      # regenerate docs/img/encounter.png from scratch:
        daa-sil campaign run --groups B-1 --encounters 60 --seed 0 --out TMP/camp
        daa-sil viz replay TMP/camp --group B-1 --worst --until 62 --rrd TMP/shot.rrd
        then the screenshot of TMP/shot.rrd (the viewer opens a file at its last step, t = 62 s)

Needs chromium (``apt-get install chromium``) and playwright (``pip install playwright``; the system
chromium is used, nothing is downloaded). The web viewer is the rerun binary bound to 127.0.0.1
(``daa_sil.viz.WebServer``) and is stopped afterwards. The image is re-encoded as an indexed PNG when
Pillow is available so it stays small.
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

from daa_sil.files import atomic_path
from daa_sil.viz import WebServer


def find_chromium() -> "str | None":
    """Path of a system chromium, or None."""
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


def screenshot(rrd: Path, out: Path, wait_s: float = 20.0, width: int = 1600, height: int = 900,
               grpc_port: int = 9877, web_port: int = 9090, when: "str | None" = None) -> Path:
    """Serve ``rrd`` on 127.0.0.1, open it in headless chromium, save ``out``."""
    from playwright.sync_api import sync_playwright

    chromium = find_chromium()
    if chromium is None:
        raise SystemExit("make_screenshot: chromium not found (apt-get install chromium)")
    server = WebServer("127.0.0.1", grpc_port, web_port, rrd=str(rrd))
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=chromium, headless=True,
                                        args=["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                                              "--ignore-gpu-blocklist"])
            page = browser.new_page(viewport={"width": width, "height": height})
            page.goto(server.url + (f"#when={when}" if when else ""), wait_until="load")
            page.wait_for_timeout(int(wait_s * 1000))
            with atomic_path(out) as tmp:
                page.screenshot(path=str(tmp), type="png")
                _shrink(tmp)
            browser.close()
    finally:
        server.stop()
    return out


def _shrink(path: Path) -> None:
    try:
        from PIL import Image
    except ImportError:
        return
    img = Image.open(path).convert("RGB").quantize(colors=256, method=Image.Quantize.MEDIANCUT)
    img.save(path, format="PNG", optimize=True)


README_IMAGE = Path(__file__).resolve().parent / "img" / "encounter.png"


def readme_image(wait_s: float = 20.0) -> Path:
    """Run a small campaign, replay its worst B-1 encounter up to t = 62 s and screenshot it."""
    import subprocess
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        cli = [sys.executable, "-m", "daa_sil.cli"]
        subprocess.run(cli + ["campaign", "run", "--groups", "B-1", "--encounters", "60", "--seed", "0",
                              "--out", str(tmp / "camp"), "--no-progress"], check=True)
        subprocess.run(cli + ["viz", "replay", str(tmp / "camp"), "--group", "B-1", "--worst", "--until", "62",
                              "--rrd", str(tmp / "shot.rrd")], check=True)
        README_IMAGE.parent.mkdir(parents=True, exist_ok=True)
        return screenshot(tmp / "shot.rrd", README_IMAGE, wait_s)


def main(argv: "list[str] | None" = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    if argv is None:
        argv = sys.argv[1:]
    if argv[:1] == ["--readme"]:
        out = readme_image()
        print(f"wrote {out} ({out.stat().st_size / 1000:.0f} kB)")
        return 0
    ap.add_argument("rrd", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--wait", type=float, default=20.0, help="seconds to let the viewer load (default 20)")
    ap.add_argument("--when", help="time cursor as a viewer URL fragment, e.g. sim_time@150s")
    ap.add_argument("--width", type=int, default=1600)
    ap.add_argument("--height", type=int, default=900)
    a = ap.parse_args(argv)
    if not a.rrd.is_file():
        print(f"make_screenshot: {a.rrd} does not exist", file=sys.stderr)
        return 2
    out = screenshot(a.rrd, a.out, a.wait, a.width, a.height, when=a.when)
    print(f"wrote {out} ({out.stat().st_size / 1000:.0f} kB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
