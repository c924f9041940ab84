"""Screenshot a rerun recording in a real headless browser (Chromium + rerun's web viewer).

    python scripts/viewer_screenshot.py out/view.rrd docs/img/viewer.png

Starts ``rerun --web-viewer --serve-web FILE`` on free ports, points headless Chromium (with
its software rasterizer, no display needed) at it, waits in real time (Chromium's
``--virtual-time-budget`` proved unreliable for the WebAssembly viewer here), takes the PNG
over the DevTools protocol and stops the processes it started (by their process ids).
Needs ``chromium`` on PATH (Debian: ``apt-get install chromium``). With the software
rasterizer the viewer takes in data slowly: a 1.6 MB recording needed about two minutes.
"""

from __future__ import annotations

import argparse
import base64
import json
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import urllib.parse
import urllib.request
from pathlib import Path


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def _rerun_binary() -> str:
    import rerun_cli  # the wheel's bundled viewer binary; calling it directly keeps its pid

    return str(Path(rerun_cli.__file__).parent / "rerun")


def _wait_for(port: int, seconds: float) -> None:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        with socket.socket() as sock:
            if sock.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.2)
    raise SystemExit(f"error: rerun web viewer did not listen on port {port}")


def _devtools_call(ws_url: str, method: str, params: dict | None = None) -> dict:
    from websockets.sync.client import connect  # installed with rerun-sdk's dependencies

    with connect(ws_url, max_size=None, open_timeout=30) as ws:
        ws.send(json.dumps({"id": 1, "method": method, "params": params or {}}))
        while True:
            reply = json.loads(ws.recv(timeout=120))
            if reply.get("id") == 1:
                return reply.get("result", {})


def _page_socket(debug_port: int, seconds: float) -> str:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        try:
            with urllib.request.urlopen(f"http://127.0.0.1:{debug_port}/json") as reply:
                pages = [p for p in json.load(reply) if p.get("type") == "page"]
            if pages:
                return pages[0]["webSocketDebuggerUrl"]
        except OSError:
            pass
        time.sleep(0.5)
    raise SystemExit("error: chromium did not open its DevTools port")


def screenshot(recording: Path, png: Path, *, width: int, height: int, wait_s: float) -> None:
    """Serve ``recording``, load it in headless Chromium, wait ``wait_s`` real seconds (the
    viewer is WebAssembly: it compiles, fetches the data and renders), save the page."""
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        raise SystemExit("error: chromium not found (Debian: apt-get install chromium)")
    web_port, grpc_port, debug_port = _free_port(), _free_port(), _free_port()
    server = subprocess.Popen(
        [_rerun_binary(), "--web-viewer", "--serve-web", str(recording),
         "--web-viewer-port", str(web_port), "--port", str(grpc_port)],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    browser_process = None
    try:
        _wait_for(web_port, 30)
        _wait_for(grpc_port, 30)
        source = urllib.parse.quote(f"rerun+http://127.0.0.1:{grpc_port}/proxy", safe="")
        with tempfile.TemporaryDirectory(ignore_cleanup_errors=True) as profile:
            browser_process = subprocess.Popen(
                [browser, "--headless", "--no-sandbox", "--use-angle=swiftshader",
                 "--enable-unsafe-swiftshader", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run",
                 f"--user-data-dir={profile}", f"--window-size={width},{height}",
                 f"--remote-debugging-port={debug_port}",
                 f"http://127.0.0.1:{web_port}?url={source}"],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            socket_url = _page_socket(debug_port, 30)
            time.sleep(wait_s)
            shot = _devtools_call(socket_url, "Page.captureScreenshot", {"format": "png"})
            png.write_bytes(base64.b64decode(shot["data"]))
            browser_process.terminate()
            browser_process.wait(timeout=20)
    finally:
        if browser_process is not None and browser_process.poll() is None:
            browser_process.kill()
        server.terminate()
        server.wait(timeout=10)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("recording", type=Path, help=".rrd file to show")
    parser.add_argument("png", type=Path, help="screenshot to write")
    parser.add_argument("--size", default="1600x1000", help="window WIDTHxHEIGHT (px)")
    parser.add_argument("--wait", type=float, default=150.0,
                        help="seconds to let the viewer load and render before the shot")
    args = parser.parse_args(argv)
    width, height = (int(v) for v in args.size.lower().split("x"))
    args.png.parent.mkdir(parents=True, exist_ok=True)
    os.environ.setdefault("RERUN_ANALYTICS", "0")
    screenshot(args.recording, args.png, width=width, height=height, wait_s=args.wait)
    print(f"wrote {args.png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
