"""Screenshots of TensorBoard showing a sweep, taken in a real headless Chromium (docs/usage.md names this script).

    python scripts/tensorboard_screenshots.py outputs/sweeps/NAME docs/tensorboard/ [--chromium /usr/bin/chromium]

Starts ``tensorboard --logdir DIR`` on a free local port and Chromium with its DevTools port, then for each view
loads the page, waits until TensorBoard has drawn, clicks what a user would click (the HParams tab's parallel
coordinates and scatter views; y log scale and no smoothing where curves are compared) and saves a PNG reduced to
a small palette. It checks what it shows: the HParams table must list every run of the sweep with the parametric
schedule's columns and the final held-out RMS as a metric, else it exits 1 naming what is missing. Needs Chromium
(Debian: ``apt-get install -y chromium``); CI does not run it. The DevTools protocol is spoken over a WebSocket
written here with the standard library (a few dozen lines), so nothing beyond TensorBoard and Pillow is needed.
"""

from __future__ import annotations

import argparse
import base64
import io
import json
import os
import shutil
import socket
import struct
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_http(url: str, seconds: float = 60) -> str:
    end = time.time() + seconds
    while time.time() < end:
        try:
            with urllib.request.urlopen(url, timeout=2) as r:
                return r.read().decode()
        except OSError:
            time.sleep(0.5)
    raise SystemExit(f"error: {url} did not answer within {seconds:.0f} s")


class DevTools:
    """A minimal Chrome DevTools Protocol client over one WebSocket (RFC 6455, client frames masked)."""

    def __init__(self, ws_url: str):
        host, path = ws_url.removeprefix("ws://").split("/", 1)
        h, p = host.split(":")
        self.sock = socket.create_connection((h, int(p)), timeout=60)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall(
            (
                f"GET /{path} HTTP/1.1\r\nHost: {host}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n"
            ).encode()
        )
        head = b""
        while b"\r\n\r\n" not in head:
            head += self.sock.recv(1)
        if b" 101 " not in head.split(b"\r\n")[0]:
            raise SystemExit(f"error: DevTools refused the WebSocket: {head[:80]!r}")
        self.next_id = 0

    def _send(self, text: str) -> None:
        data, mask = text.encode(), os.urandom(4)
        n = len(data)
        head = bytes([0x81]) + (
            bytes([0x80 | n]) if n < 126 else bytes([0xFE]) + struct.pack(">H", n) if n < 65536
            else bytes([0xFF]) + struct.pack(">Q", n)
        )  # fmt: skip
        self.sock.sendall(head + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(data)))

    def _exact(self, n: int) -> bytes:
        out = b""
        while len(out) < n:
            chunk = self.sock.recv(n - len(out))
            if not chunk:
                raise SystemExit("error: DevTools closed the connection")
            out += chunk
        return out

    def _recv(self) -> str:
        parts = b""
        while True:
            b0, b1 = self._exact(2)
            n = b1 & 0x7F
            n = (
                struct.unpack(">H", self._exact(2))[0]
                if n == 126
                else struct.unpack(">Q", self._exact(8))[0]
                if n == 127
                else n
            )
            parts += self._exact(n)
            if b0 & 0x80:
                return parts.decode()

    def call(self, method: str, **params):
        self.next_id += 1
        self._send(json.dumps({"id": self.next_id, "method": method, "params": params}))
        while True:
            msg = json.loads(self._recv())
            if msg.get("id") == self.next_id:
                if "error" in msg:
                    raise SystemExit(f"error: DevTools {method}: {msg['error']}")
                return msg.get("result", {})

    def js(self, expression: str):
        r = self.call("Runtime.evaluate", expression=expression, returnByValue=True, awaitPromise=True)
        return r.get("result", {}).get("value")


# every element, shadow roots included (TensorBoard's dashboards are Polymer and Angular components)
DEEP = """
function deep(pred) { const out = []; const walk = n => { if (!n) return; if (n.nodeType === 1 && pred(n)) out.push(n);
  if (n.shadowRoot) walk(n.shadowRoot); for (const c of (n.children || [])) walk(c); }; walk(document.documentElement);
  return out; }
function clickText(text) { const hits = deep(n => (n.innerText || '').trim().toUpperCase() === text.toUpperCase());
  const el = hits[hits.length - 1]; if (el) { el.click(); return true; } return false; }
function noSmoothing() { const found = deep(n => n.tagName === 'INPUT' && n.type === 'number' && n.value === '0.6');
  found.forEach(i => { i.value = '0';
    ['input', 'change'].forEach(e => i.dispatchEvent(new Event(e, {bubbles: true}))); });
  return found.length; }
function clickLabel(re) {
  const hits = deep(n => re.test(n.getAttribute('aria-label') || n.getAttribute('title') || ''));
  hits.forEach(h => h.click()); return hits.length; }
"""


def shoot(dev: DevTools, url: str, actions: list[str], path: Path, wait: float) -> None:
    dev.call("Page.navigate", url=url)
    time.sleep(wait)
    for a in actions:
        dev.js(DEEP + a)
        time.sleep(wait / 2)
    png = base64.b64decode(dev.call("Page.captureScreenshot", format="png")["data"])
    from PIL import Image

    img = Image.open(io.BytesIO(png)).convert("RGB").quantize(colors=96)
    path.parent.mkdir(parents=True, exist_ok=True)
    img.save(path, optimize=True)
    print(f"{path} ({path.stat().st_size // 1024} KB)")


VIEWS = [  # (file, TensorBoard URL fragment, clicks in the page after it loads)
    ("hparams_table.png", "#hparams", []),
    ("hparams_parallel_coordinates.png", "#hparams", ["clickText('PARALLEL COORDINATES VIEW')"]),
    ("hparams_scatter.png", "#hparams", ["clickText('SCATTER PLOT MATRIX VIEW')"]),
    ("custom_scalars.png", "#custom_scalars", ["noSmoothing()", "clickLabel(/log/i)"]),
    ("time_series.png", "#timeseries", []),
]


def check(dev: DevTools, runs: int) -> list[str]:
    """What the HParams table must show: a row for every run, the schedule's columns, the final RMS as a metric."""
    dev.call("Page.navigate", url=dev.base + "#hparams")
    time.sleep(dev.wait)
    text = dev.js(DEEP + "deep(n => !!n.shadowRoot).map(n => n.shadowRoot.textContent).join(' ')") or ""
    wanted = ("p", "n1", "sum N_i", "growth", "N_i rule", "cost (presentations)", "final/heldout_rms_nm")
    problems = [f"the HParams tab shows no column {w!r}" for w in wanted if w not in text]
    rows = dev.js(DEEP + "Math.max(0, ...deep(n => n.tagName === 'VAADIN-GRID').map(g => (g.items || []).length))")
    if rows != runs:
        problems.append(f"the HParams table has {rows} rows for {runs} runs")
    return problems


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("logdir", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--chromium", default=shutil.which("chromium") or shutil.which("chromium-browser") or "chromium")
    ap.add_argument("--wait", type=float, default=8.0, help="seconds for TensorBoard to draw a view")
    a = ap.parse_args(argv)
    runs = len({p.parent for p in a.logdir.rglob("events.out.tfevents.*") if not p.name.endswith(".sweep.selpres")})
    if not runs:
        print(f"error: no TensorBoard event files under {a.logdir}", file=sys.stderr)
        return 2
    tb_port, cdp_port = free_port(), free_port()
    tb = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "tensorboard.main",
            "--logdir",
            str(a.logdir),
            "--host",
            "127.0.0.1",
            "--port",
            str(tb_port),
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    profile = tempfile.mkdtemp(prefix="selpres-chromium-")
    chrome = subprocess.Popen(
        [a.chromium, "--headless", "--no-sandbox", "--disable-gpu", f"--remote-debugging-port={cdp_port}",
         f"--user-data-dir={profile}", "--window-size=1500,950", "--hide-scrollbars", "about:blank"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )  # fmt: skip
    try:
        base = f"http://127.0.0.1:{tb_port}/"
        wait_http(base + "data/runs", 90)
        time.sleep(3)  # the first reload of the event files
        targets = json.loads(wait_http(f"http://127.0.0.1:{cdp_port}/json/list", 60))
        page = next(t for t in targets if t.get("type") == "page")
        dev = DevTools(page["webSocketDebuggerUrl"])
        dev.base, dev.wait = base, a.wait
        dev.call("Page.enable")
        dev.call("Emulation.setDeviceMetricsOverride", width=1500, height=950, deviceScaleFactor=1, mobile=False)
        problems = check(dev, runs)
        for name, frag, actions in VIEWS:
            shoot(dev, base + frag, actions, a.out / name, a.wait)
    finally:
        chrome.terminate()
        tb.terminate()
        chrome.wait(10)
        tb.wait(10)
        shutil.rmtree(profile, ignore_errors=True)
    for p in problems:
        print(f"error: {p}", file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
