"""Load test of the browser app (issue 15): five people clicking and uploading at once.

    make loadtest     (or: .venv/bin/python benchmarks/load_test.py [--seconds 120] [--seed N])

Starts `roachplan serve` on a free port and opens 5 headless Chromium pages (one browser, one
context each: five sessions). For --seconds each page loops: click Plan, click Drive, and every
few rounds upload a file, alternating a good one (a small .stl written here, a library .scad) and
a bad one (random bytes named .pcd, an empty .ply, a YAML billion-laughs, a truncated PNG).
Every pause, file choice and random byte comes from one numpy generator seeded by --seed.

Measured per page: clicks sent (Plan, Drive and Load file), clicks answered, and the time from
a click to the page's answer (median and max). An answer is text the page shows after the click
that belongs to that command: a notification to this page ("Plan queued", "Nothing to drive",
an upload error) or the shared status line ("Planning with ...", "Drive: 12 % ...", "Loaded
...") -- the status is shared, so another page's command may answer first. A click left with
no answer for 30 s is lost. At the end each page clicks Plan once more and must be answered
within 30 s; the server must still answer HTTP, and its log (stdout and stderr) must hold no
'Traceback' (lines with 'Error' are counted and shown). Exit status 1 if any of these fails.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh

ROOT = Path(__file__).resolve().parent.parent
LIBRARY = ROOT / "scenes" / "library"
PAGES = 5
ANSWER_S = 30.0
"""How long a click may wait for its answer [s]."""
ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--no-first-run",
]

# What each command's answer looks like (JavaScript regular expressions on the page's new text).
PLAN = r"Plan|Path found|No path|path\(s\)|Start and goal"
DRIVE = r"Driv|Trial \d|Nothing to drive"
UPLOAD = r"[Ll]oad|[Uu]pload|[Ee]rror|not a|empty|cannot|too large|[Rr]ender|OpenSCAD"

# Every text the page adds or changes, with its time (performance.now() [ms]); the last 4000.
OBSERVER = """
window.__ev = [];
new MutationObserver((records) => {
  const t = performance.now();
  for (const r of records) {
    const nodes = r.type === "characterData" ? [r.target] : [...r.addedNodes];
    for (const n of nodes) {
      const text = (n.textContent || "").slice(0, 400);
      if (text) window.__ev.push({t, text});
    }
  }
  if (window.__ev.length > 4000) window.__ev.splice(0, 1000);
}).observe(document, {subtree: true, childList: true, characterData: true});
"""
ANSWERED = """([t0, src]) => {
  const re = new RegExp(src);
  const e = window.__ev.find((e) => e.t >= t0 && re.test(e.text));
  return e ? e.t : null;
}"""


@dataclass
class PageStats:
    """What one page sent and saw."""

    clicks: int = 0
    """Clicks sent (Plan, Drive, Load file)."""
    uploads: int = 0
    """Of those, files uploaded."""
    answered: int = 0
    """Clicks answered within ANSWER_S."""
    latencies: list[float] = field(default_factory=list)
    """Click-to-answer times [s]."""
    errors: list[str] = field(default_factory=list)
    """JavaScript errors on the page, and clicks Playwright could not make."""
    final: float | None = None
    """The last Plan click's answer time [s]; None: no answer within ANSWER_S."""
    rows: int = 0
    """Rows of the trials table at the end."""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def write_files(folder: Path, rng: np.random.Generator) -> tuple[list[Path], list[Path]]:
    """(good, bad) files to upload."""
    steps = [trimesh.creation.box((0.6, 1.0, h)) for h in (0.02, 0.04, 0.06)]
    for k, box in enumerate(steps):
        box.apply_translation((0.0, 1.0 * k - 1.0, box.extents[2] / 2))
    stl = folder / "steps.stl"
    trimesh.util.concatenate(steps).export(stl)
    pcd = folder / "noise.pcd"
    pcd.write_bytes(rng.bytes(4096))
    ply = folder / "empty.ply"
    ply.write_bytes(b"")
    laughs = ["a: &a [lol, lol, lol, lol, lol, lol, lol, lol, lol]"]
    for prev, name in zip("abcdefgh", "bcdefghi"):
        laughs.append(f"{name}: &{name} [" + ", ".join([f"*{prev}"] * 9) + "]")
    yml = folder / "laughs.yaml"
    yml.write_text("\n".join(laughs) + "\n")
    png = folder / "cut.png"
    whole = (LIBRARY / "kinect_bridge_depth.png").read_bytes()
    png.write_bytes(whole[: int(rng.integers(100, len(whole) // 2))])
    return [stl, LIBRARY / "double_bridge.scad"], [pcd, ply, yml, png]


async def answer_time(page, t0: float, pattern: str) -> float | None:
    """Seconds from t0 (the page's clock [ms]) to the first new text matching pattern."""
    try:
        handle = await page.wait_for_function(
            ANSWERED, arg=[t0, pattern], timeout=ANSWER_S * 1000, polling=100
        )
    except Exception:  # (Playwright's TimeoutError)
        return None
    return (await handle.json_value() - t0) / 1000


async def act(page, stats: PageStats, what: str, path: Path | None = None) -> float | None:
    """Click Plan or Drive, or upload path; wait for the answer; note it."""
    t0 = await page.evaluate("performance.now()")
    stats.clicks += 1
    try:  # (a page too busy to take the click within 30 s counts as a lost click)
        if path is None:
            await page.get_by_role("button", name=what).click(no_wait_after=True)
        else:
            async with page.expect_file_chooser() as chooser:
                await page.get_by_role("button", name="Load file").click(no_wait_after=True)
            await (await chooser.value).set_files(str(path))
            stats.uploads += 1
    except Exception as exc:  # (Playwright's TimeoutError)
        stats.errors.append(f"{what}: {exc}".splitlines()[0])
        return None
    took = await answer_time(page, t0, {"Plan": PLAN, "Drive": DRIVE}.get(what, UPLOAD))
    if took is not None:
        stats.answered += 1
        stats.latencies.append(took)
    return took


async def user(page, stats: PageStats, rng, files, *, k: int, until: float) -> None:
    """One person: Plan, Drive, and every few rounds a file, good and bad in turn."""
    good, bad = files
    uploaded, next_upload = 0, int(rng.integers(2, 5))
    for r in range(10**9):
        if time.monotonic() >= until:
            break
        for what in ("Plan", "Drive"):
            await act(page, stats, what)
            await asyncio.sleep(float(rng.uniform(0.2, 2.0)))
        if r + 1 == next_upload:
            pool = good if (uploaded + k) % 2 == 0 else bad
            await act(page, stats, "Load file", pool[int(rng.integers(len(pool)))])
            uploaded, next_upload = uploaded + 1, next_upload + int(rng.integers(2, 5))
    stats.final = await act(page, stats, "Plan")
    stats.rows = max(await page.locator("table").first.get_by_role("row").count() - 1, 0)


async def load(url: str, seconds: float, rngs, files) -> list[PageStats]:
    from playwright.async_api import async_playwright

    async with async_playwright() as pw:
        browser = await pw.chromium.launch(executable_path=shutil.which("chromium"), args=ARGS)
        stats = [PageStats() for _ in range(PAGES)]
        pages = []
        for s in stats:
            page = await (
                await browser.new_context(viewport={"width": 1280, "height": 900})
            ).new_page()
            page.on("pageerror", lambda exc, s=s: s.errors.append(str(exc)))
            await page.add_init_script(OBSERVER)
            await page.goto(url)
            await page.get_by_role("button", name="Plan").wait_for(timeout=60_000)
            pages.append(page)
        # Faster playback (shared by all pages), so that drives end within the run.
        row = pages[0].locator(
            "xpath=//label[text()='Playback speed [x real time]']/ancestor::div[.//input][1]"
        )
        await row.locator("input").last.fill("10")
        await row.locator("input").last.press("Enter")
        until = time.monotonic() + seconds
        await asyncio.gather(
            *(
                user(p, s, r, files, k=k, until=until)
                for k, (p, s, r) in enumerate(zip(pages, stats, rngs))
            )
        )
        await browser.close()
    return stats


def start_server(log: Path) -> tuple[subprocess.Popen, str]:
    port = free_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "roachplan", "serve", "--port", str(port)],
        cwd=ROOT,
        stdout=log.open("w"),
        stderr=subprocess.STDOUT,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        for line in log.read_text().splitlines():
            if line.startswith("roachplan: serving"):
                return proc, line.rsplit(" at ", 1)[1].strip()
        time.sleep(0.2)
    proc.kill()
    sys.exit(f"load_test: the server did not start:\n{log.read_text()}")


def answers_http(url: str) -> bool:
    try:
        with urllib.request.urlopen(url, timeout=10) as r:
            return r.status == 200
    except OSError:
        return False


def main() -> int:
    assert __doc__ is not None
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=120.0, help="how long the pages click [s]")
    parser.add_argument("--seed", type=int, default=int(time.time()) % 100_000)
    args = parser.parse_args()
    if shutil.which("chromium") is None:
        sys.exit("load_test: needs Debian's chromium (make test installs it)")
    print(f"load_test: seed {args.seed}, {PAGES} pages, {args.seconds:g} s")
    rng = np.random.default_rng(args.seed)
    with tempfile.TemporaryDirectory() as tmp:
        files = write_files(Path(tmp), rng)
        proc, url = start_server(Path(tmp) / "server.log")
        try:
            stats = asyncio.run(load(url, args.seconds, rng.spawn(PAGES), files))
            alive = answers_http(url)
        finally:
            proc.terminate()
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
        log = (Path(tmp) / "server.log").read_text()

    print(
        f"{'page':>4} {'clicks':>6} {'uploads':>7} {'answered':>8} {'lost':>4} "
        f"{'median [s]':>10} {'max [s]':>7} {'last Plan [s]':>13} {'trials':>6} {'page errors':>11}"
    )
    for k, s in enumerate(stats):
        lat = s.latencies or [float("nan")]
        last = "none" if s.final is None else f"{s.final:.2f}"
        print(
            f"{k + 1:>4} {s.clicks:>6} {s.uploads:>7} {s.answered:>8} {s.clicks - s.answered:>4} "
            f"{statistics.median(lat):>10.2f} {max(lat):>7.2f} {last:>13} {s.rows:>6} "
            f"{len(s.errors):>11}"
        )
    for k, s in enumerate(stats):
        for e in s.errors[:3]:
            print(f"  page {k + 1}: {e[:200]}")
    tracebacks = log.count("Traceback")
    errors = [line for line in log.splitlines() if "Error" in line]
    print(
        f"server: answers HTTP at the end: {'yes' if alive else 'NO'}; "
        f"'Traceback' in its log: {tracebacks}; lines with 'Error': {len(errors)}"
    )
    for line in errors[:10]:
        print(f"  | {line[:200]}")
    lost = sum(s.clicks - s.answered for s in stats)
    dead = sum(s.final is None for s in stats)
    ok = alive and not tracebacks and not lost and not dead
    print(
        "load_test: "
        + (
            "PASS"
            if ok
            else f"FAIL ({lost} lost click(s), {dead} unresponsive "
            f"page(s), {tracebacks} traceback(s))"
        )
    )
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
