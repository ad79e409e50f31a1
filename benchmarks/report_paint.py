"""How long a browser takes to show the first screen of report.html: headless Chromium, first paint.

Each measurement starts a fresh headless Chromium (``--remote-debugging-pipe``: the DevTools
protocol over two pipes, no network port, standard library only), opens a blank tab, turns on
the page's lifecycle events, sends ``Page.navigate`` to ``file://REPORT`` and waits for the
``firstContentfulPaint`` lifecycle event (and then ``load``). Reported per file: the wall time
from the navigate command to that event as this process sees it, the page's own
``first-contentful-paint`` entry (Performance API, ms after navigation start) and the time to
``load``; then, in another fresh browser, the wall time of ``chromium --headless --screenshot``
of the page's first screen (``shot s``: browser start, load, paint). Medians over ``--repeats``,
the files measured alternately so that the machine's load falls on each alike. Also the bytes of
the HTML and of the files beside it that it references (``report_files/``).

    python benchmarks/report_paint.py RUN/report.html OTHER/report.html [--repeats 5] [--width 1280]

Measured on 2026-11-25, 2 cores shared with other jobs (load average 14-18), medians of 3, the
files alternated. ``before``: the report as main wrote it (c8373f4: pictures inline as base64 PNG,
the trajectories figure inline SVG); ``after``: this tree (pictures in ``report_files/``, lazy).
``mini``: 2 presets (nominal, jitter) x 1 seed x the 7 standard pipelines, 20 frames. ``x9``: the
scene blocks (pictures, stabilisation, tracking) of a real 60-frame nominal run with the 7
pipelines, repeated 9 times in one page: the size of the ``standard`` report (its 9 scenes; 140.6
MB against the 143.6 MB of issue 23), built from real blocks because ``standard`` cannot run here.

    file            HTML MB  files MB  FCP s  FCP page s  load s  shot s
    mini   before     27.49      0.00   0.74        0.62    3.28    7.31
    mini   after       0.34      1.82   0.79        0.51    0.61    5.52
    x9     before    140.60      0.00   0.54        0.37   48.82   47.65
    x9     after       1.67      1.28   1.61        0.90    2.23    6.58

Chromium paints the top of a page before it has parsed the rest, so the first contentful paint is
early either way; the wait a person sees is ``load`` (the screenshot command waits for it, and
``shot s`` adds the browser's start, about 5 s on this loaded machine). Per 60-frame scene block
the page held 15.4 MB (pictures 13.5, trajectories 2.0); now 0.16 MB in the page and 1.28 MB of
files (64 WebP pictures 0.35 MB, the trajectories SVG 0.92 MB; the x9 page repeats one block, so
its files are one block's), so ``standard`` comes to about 2 MB of HTML and 11 MB of files.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
          "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-extensions",
          "--remote-debugging-pipe"]


class _Pipe:
    """The DevTools protocol over Chromium's pipes: NUL-terminated JSON messages."""

    def __init__(self, proc: subprocess.Popen, to_browser: int, from_browser: int):
        self.proc, self.w, self.r = proc, to_browser, from_browser
        self.buf = b""
        self.next_id = 0
        self.events: list[tuple[float, dict]] = []  # (perf_counter when read, message)

    def send(self, method: str, params: dict | None = None, session: str | None = None) -> int:
        self.next_id += 1
        msg = {"id": self.next_id, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = session
        os.write(self.w, json.dumps(msg).encode() + b"\0")
        return self.next_id

    def _read(self, deadline: float) -> dict:
        while b"\0" not in self.buf:
            if time.perf_counter() > deadline:
                raise TimeoutError("no answer from Chromium")
            chunk = os.read(self.r, 1 << 20)
            if not chunk:
                raise RuntimeError("Chromium closed its pipe")
            self.buf += chunk
        raw, self.buf = self.buf.split(b"\0", 1)
        return json.loads(raw)

    def call(self, method: str, params: dict | None = None, session: str | None = None,
             timeout_s: float = 120.0) -> dict:
        i = self.send(method, params, session)
        deadline = time.perf_counter() + timeout_s
        while True:
            m = self._read(deadline)
            if m.get("id") == i:
                if "error" in m:
                    raise RuntimeError(f"{method}: {m['error']}")
                return m.get("result", {})
            self.events.append((time.perf_counter(), m))

    def wait_event(self, pred, timeout_s: float = 300.0) -> tuple[float, dict]:
        for k, (t, m) in enumerate(self.events):
            if pred(m):
                return self.events.pop(k)
        deadline = time.perf_counter() + timeout_s
        while True:
            m = self._read(deadline)
            t = time.perf_counter()
            if pred(m):
                return t, m
            self.events.append((t, m))


def _lifecycle(name: str):
    return lambda m: m.get("method") == "Page.lifecycleEvent" and m["params"].get("name") == name


def measure(html: Path, *, width: int, height: int, chromium: str) -> dict[str, float]:
    """One fresh browser: seconds from navigate to first contentful paint (as seen here and as the
    page's Performance API has it) and to load."""
    to_r, to_w = os.pipe()      # we write, Chromium reads on its fd 3
    from_r, from_w = os.pipe()  # Chromium writes on its fd 4, we read
    profile = tempfile.mkdtemp(prefix="report-paint-")
    # the child's ends onto its fds 3 and 4 (dup2 leaves them inheritable; every other pipe end is
    # close-on-exec, so close_fds=False passes exactly these two)
    def child_fds() -> None:
        r, w = os.dup(to_r), os.dup(from_w)  # either end may be 3 or 4 itself: moved out of the way first
        os.dup2(r, 3)
        os.dup2(w, 4)

    proc = subprocess.Popen([chromium, *_FLAGS, f"--user-data-dir={profile}", f"--window-size={width},{height}",
                             "about:blank"], preexec_fn=child_fds, close_fds=False,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    os.close(to_r)
    os.close(from_w)
    pipe = _Pipe(proc, to_w, from_r)
    try:
        target = pipe.call("Target.createTarget", {"url": "about:blank"})["targetId"]
        session = pipe.call("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
        pipe.call("Page.enable", session=session)
        pipe.call("Page.setLifecycleEventsEnabled", {"enabled": True}, session=session)
        pipe.events.clear()
        t0 = time.perf_counter()
        pipe.call("Page.navigate", {"url": html.resolve().as_uri()}, session=session, timeout_s=300.0)
        t_fcp, _ = pipe.wait_event(_lifecycle("firstContentfulPaint"))
        t_load, _ = pipe.wait_event(_lifecycle("load"))
        fcp_ms = pipe.call("Runtime.evaluate", {
            "expression": "(performance.getEntriesByName('first-contentful-paint')[0] || {startTime: NaN}).startTime",
            "returnByValue": True}, session=session)["result"].get("value")
        # NaN when the page has no such entry (JSON null)
        fcp_page_s = float(fcp_ms) / 1000.0 if isinstance(fcp_ms, (int, float)) else float("nan")
        return {"fcp_s": t_fcp - t0, "fcp_page_s": fcp_page_s, "load_s": t_load - t0}
    finally:
        try:
            pipe.send("Browser.close")
            proc.wait(timeout=20)
        except (OSError, subprocess.TimeoutExpired):
            proc.kill()
            proc.wait()
        os.close(to_w)
        os.close(from_r)
        shutil.rmtree(profile, ignore_errors=True)


def screenshot_s(html: Path, *, width: int, height: int, chromium: str) -> float:
    """Wall seconds of ``chromium --headless --screenshot`` of the page (what a person running that command
    waits for: browser start, the page's load, its first screen painted into a PNG)."""
    profile = tempfile.mkdtemp(prefix="report-paint-")
    try:
        t0 = time.perf_counter()
        subprocess.run([chromium, *_FLAGS[:-1], f"--user-data-dir={profile}", f"--window-size={width},{height}",
                        f"--screenshot={profile}/shot.png", html.resolve().as_uri()], check=True,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=600)
        return time.perf_counter() - t0
    finally:
        shutil.rmtree(profile, ignore_errors=True)


def _bytes(html: Path) -> tuple[int, int]:
    side = html.parent / "report_files"
    return html.stat().st_size, sum(p.stat().st_size for p in side.rglob("*") if p.is_file()) if side.is_dir() else 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("html", nargs="+", type=Path, help="report.html files, measured alternately")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--width", type=int, default=1280)
    ap.add_argument("--height", type=int, default=900)
    ap.add_argument("--chromium", default=shutil.which("chromium") or "chromium")
    args = ap.parse_args(argv)
    runs: dict[Path, list[dict[str, float]]] = {h: [] for h in args.html}
    for _ in range(args.repeats):
        for h in args.html:
            r = measure(h, width=args.width, height=args.height, chromium=args.chromium)
            r["shot_s"] = screenshot_s(h, width=args.width, height=args.height, chromium=args.chromium)
            runs[h].append(r)
    print(f"{'file':44s} {'HTML MB':>8s} {'files MB':>8s} {'FCP s':>7s} {'FCP page s':>10s} {'load s':>7s} "
          f"{'shot s':>7s}")
    for h, rs in runs.items():
        html_b, side_b = _bytes(h)
        med = {k: statistics.median([r[k] for r in rs if r[k] == r[k]] or [float("nan")]) for k in rs[0]}
        print(f"{str(h)[-44:]:44s} {html_b / 1e6:8.2f} {side_b / 1e6:8.2f} {med['fcp_s']:7.2f} "
              f"{med['fcp_page_s']:10.2f} {med['load_s']:7.2f} {med['shot_s']:7.2f}   (medians of {len(rs)})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
