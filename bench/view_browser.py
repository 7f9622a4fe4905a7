"""A finished recording as a person sees it: Rerun's web viewer in headless Chromium, no clicks.

    .venv/bin/python bench/view_browser.py RUN/campaign.rrd [--out DIR] [--timeout 600] [--no-tabs]

Needs Debian's ``chromium`` package (``apt-get install chromium``); Playwright (in the venv,
requirements-dev.txt) drives it and downloads no browser. Everything listens on 127.0.0.1, on
ports the OS picks: a static file server for the recording, and Rerun's web viewer
(``rerun --serve-web``, the SDK's own binary). The page is opened the way a person opens a
file, ``http://VIEWER/?url=http://FILES/campaign.rrd``; the viewer may reach nothing else.

1. ``opened.png``: the recording as it opens. The page is screenshot about once a second until
   ``--settle`` screenshots in a row are the same. Seconds to data: the first screenshot with
   at least 90 % of the final screenshot's coloured pixels (plot lines and bars are coloured,
   the viewer's own interface is gray); seconds to settled: the first of the unchanged ones.
2. ``tab_<name>.png``, one per tab under the C_l–α view (blueprint.TABS): a copy of the
   recording with one more blueprint appended, the recording's layout with that tab active
   (a recording shows the last blueprint it holds; its levels are read back from the recording
   with Rerun's reader). The viewer applies that blueprint once it has read the whole file: a
   large recording shows its own layout until then (docs/results.md gives the load times).

Chromium runs with ``--no-sandbox`` (root) and WebGL on its software renderer (SwiftShader);
the viewer falls back from WebGPU to WebGL by itself, ``renderer=webgl`` asks for it directly.
Last line: JSON with the seconds to data and to settled per page and the screenshots' paths.
"""

import argparse
import contextlib
import functools
import http.server
import io
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
import urllib.parse
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from aero_rig.view import slug
from aero_rig.view.blueprint import TABS, make_blueprint
from aero_rig.view.readback import entity_rows

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_FLAGS = (
    "--no-sandbox",  # root
    "--use-angle=swiftshader",  # WebGL 2 on the CPU: there is no GPU
    "--enable-unsafe-swiftshader",
    "--disable-background-networking",
    "--disable-component-update",
    "--no-first-run",
    "--disable-dev-shm-usage",
)
LOCAL = re.compile(r"^https?://127\.0\.0\.1[:/]")
ANSI = re.compile(r"\x1b\[[0-9;]*m")


class _Files(http.server.SimpleHTTPRequestHandler):
    """Static files with CORS (the viewer's page is on another port)."""

    def end_headers(self) -> None:
        self.send_header("Access-Control-Allow-Origin", "*")
        super().end_headers()

    def log_message(self, *args: Any) -> None:
        pass


@contextlib.contextmanager
def file_server(root: Path) -> Iterator[str]:
    server = http.server.ThreadingHTTPServer(
        ("127.0.0.1", 0), functools.partial(_Files, directory=str(root))
    )
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}"
    finally:
        server.shutdown()
        server.server_close()


def rerun_binary() -> Path:
    """The viewer binary of the installed rerun-sdk (the ``rerun`` script is a wrapper that
    starts it as a child: stopping the wrapper would leave the binary running)."""
    import rerun_cli

    return Path(rerun_cli.__file__).with_name("rerun")


@contextlib.contextmanager
def web_viewer(log: Path, timeout_s: float = 60.0) -> Iterator[str]:
    """``rerun --serve-web`` on 127.0.0.1 in its own process group; yields the viewer's URL."""
    env = dict(os.environ, BROWSER="true")  # never open a desktop browser
    cmd = [str(rerun_binary()), "--serve-web", "--bind", "127.0.0.1", "--port", "0",
           "--web-viewer-port", "0"]  # fmt: skip
    with log.open("w") as out:
        proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, env=env,
                                start_new_session=True)  # fmt: skip
    try:
        deadline = time.monotonic() + timeout_s
        url = None
        while url is None:
            if proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(
                    f"rerun --serve-web gave no viewer URL: {log.read_text()[-2000:]}"
                )
            found = re.search(
                r"web-viewer at (http://127\.0\.0\.1:\d+)", ANSI.sub("", log.read_text())
            )
            url = found[1] if found else None
            if url is None:
                time.sleep(0.1)  # polling the log for a line, bounded by the deadline
        yield url
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(10)


def _pixels(png: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.int16)


def coloured_pixels(image: np.ndarray) -> int:
    """Strongly coloured pixels: the plots' lines, points and bars (the viewer's chrome is gray)."""
    top, bottom = image.max(axis=2), image.min(axis=2)
    return int(np.count_nonzero((top - bottom > 80) & (top > 90)))


def watch(browser: Any, url: str, png: Path, timeout_s: float, settle: int) -> dict[str, Any]:
    """Open ``url`` in a fresh context, screenshot until ``settle`` in a row are the same."""
    context = browser.new_context(viewport={"width": 1600, "height": 1000})
    page = context.new_page()
    page.route(re.compile(r"^https?://.*"), lambda route: (
        route.continue_() if LOCAL.match(route.request.url) else route.abort()
    ))  # fmt: skip
    errors: list[str] = []
    page.on("pageerror", lambda exc: errors.append(str(exc)[:300]))
    started = time.monotonic()
    page.goto(url, wait_until="load")
    shots: list[tuple[float, int, bool]] = []  # (s, coloured pixels, same as the one before)
    previous, same, last = None, 0, b""
    while True:
        t = time.monotonic() - started
        last = page.screenshot(type="png")
        image = _pixels(last)
        unchanged = previous is not None and bool(np.array_equal(previous, image))
        same = same + 1 if unchanged else 0
        shots.append((round(t, 2), coloured_pixels(image), unchanged))
        previous = image
        if (same >= settle and shots[-1][1] > 0) or t > timeout_s:
            break
    context.close()
    png.write_bytes(last)
    final = shots[-1][1]
    to_data = next((t for t, n, _ in shots if final and n >= 0.9 * final), None)
    changed = [t for t, _, unchanged in shots if not unchanged]
    return {
        "png": str(png),
        "seconds_to_data": to_data,
        "seconds_to_settled": changed[-1] if same >= settle else None,
        "coloured_pixels": final,
        "screenshots": len(shots),
        "page_errors": errors[:5],
    }


def recording_levels(rrd: Path) -> list[str]:
    """The levels of a recording (its FRF entities), read with Rerun's reader (paths only)."""
    return sorted({p.split("/")[2].removeprefix("level_") for p in entity_rows(rrd)
                   if p.startswith("/frf/level_")})  # fmt: skip


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "rrd", type=Path, help="a finished recording (aero-rig campaign --rerun save)"
    )
    parser.add_argument("--out", type=Path, default=Path("view_screenshots"), help="PNG directory")
    parser.add_argument("--timeout", type=float, default=600.0, help="longest watch per page [s]")
    parser.add_argument("--settle", type=int, default=4, help="unchanged screenshots that end it")
    parser.add_argument("--tabs", action=argparse.BooleanOptionalAction, default=True,
                        help="also one screenshot per tab")  # fmt: skip
    parser.add_argument("--chromium", default=CHROMIUM)
    args = parser.parse_args()
    if not Path(args.chromium).exists():
        print(f"no browser at {args.chromium}: apt-get install chromium", file=sys.stderr)
        return 2
    from playwright.sync_api import sync_playwright

    args.out.mkdir(parents=True, exist_ok=True)
    levels = recording_levels(args.rrd)
    figures: dict[str, Any] = {"levels": levels}
    with tempfile.TemporaryDirectory(prefix="view_browser_") as tmp:
        served = Path(tmp) / "files"
        served.mkdir()
        pages = {"opened": served / "opened.rrd"}
        os.symlink(args.rrd.resolve(), pages["opened"])
        for tab in TABS if args.tabs else ():
            copy = served / f"tab_{slug(tab)}.rrd"
            shutil.copyfile(args.rrd, copy)
            blueprint = Path(tmp) / f"{slug(tab)}.rbl"
            make_blueprint(levels, active_tab=tab).save("aero_rig", str(blueprint))
            with copy.open("ab") as out:  # .rrd and .rbl are streams of messages: they chain
                out.write(blueprint.read_bytes())
            pages[f"tab_{slug(tab)}"] = copy
        with (
            file_server(served) as files,
            web_viewer(Path(tmp) / "rerun.log") as viewer,
            sync_playwright() as playwright,
        ):
            browser = playwright.chromium.launch(
                executable_path=args.chromium, args=list(CHROMIUM_FLAGS), chromium_sandbox=False
            )
            try:
                for name, path in pages.items():
                    query = urllib.parse.urlencode(
                        {"persist": "0", "renderer": "webgl", "url": f"{files}/{path.name}"}
                    )
                    result = watch(browser, f"{viewer}/?{query}", args.out / f"{name}.png",
                                   args.timeout, args.settle)  # fmt: skip
                    figures[name] = result
                    data, settled = result["seconds_to_data"], result["seconds_to_settled"]
                    print(f"{name}: data after {data} s, settled after {settled} s", flush=True)
            finally:
                browser.close()
    print(json.dumps(figures))
    return 0


if __name__ == "__main__":
    sys.exit(main())
