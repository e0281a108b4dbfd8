"""The app as a person uses it, in headless Chromium (Debian's package, driven by Playwright):
open the page, Plan, see a path, Drive, see the trial's row with its energy, Reset."""

from __future__ import annotations

import re
import shutil

import pytest

CHROMIUM = shutil.which("chromium")
pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(CHROMIUM is None, reason="Debian chromium not installed"),
]


@pytest.fixture
def page(server_url, artifacts):
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        browser = pw.chromium.launch(
            executable_path=CHROMIUM,
            args=[
                "--no-sandbox",
                "--disable-gpu",
                "--disable-background-networking",
                "--disable-component-update",
                "--no-first-run",
            ],
        )
        page = browser.new_page(viewport={"width": 1280, "height": 800})
        errors: list[str] = []
        page.on("pageerror", lambda exc: errors.append(str(exc)))
        page.goto(server_url)
        yield page
        browser.close()
        assert not errors, f"page errors: {errors}"


def test_plan_drive_reset_in_the_browser(page, artifacts):
    plan = page.get_by_role("button", name="Plan")
    plan.wait_for(timeout=60_000)
    page.screenshot(path=artifacts / "01-loaded.png")
    plan.click()
    page.get_by_text(re.compile(r"Path found in")).wait_for(timeout=60_000)
    page.screenshot(path=artifacts / "02-planned.png")

    drive = page.get_by_role("button", name="Drive")
    drive.click()
    # The drive plays back at real time (up to 60 s simulated).
    status = page.get_by_text(re.compile(r"Trial 1: "))
    status.wait_for(timeout=120_000)
    page.screenshot(path=artifacts / "03-driven.png")
    text = status.inner_text()
    assert re.search(r"\*?\*?(success|fell|flipped|stuck|timeout)", text), text
    assert re.search(r"\d+\.\d{3} J", text), text
    # The trials table gained a row with the same outcome and an energy value.
    rows = page.locator("table").first.get_by_role("row")
    assert rows.count() == 2, "header and one trial"
    cells = [c.strip() for c in rows.nth(1).inner_text().split("\t")]
    assert cells[0] == "1" and cells[3] in ("success", "fell", "flipped", "stuck", "timeout"), cells
    assert float(cells[5]) > 0, cells  # energy [J]
    assert float(cells[6]) > 0.5, cells  # relative energy: at least half a floor walk

    page.get_by_role("button", name="Reset").click()
    page.get_by_text("Robot back at the start.").wait_for(timeout=30_000)
    plan.click()
    page.get_by_text(re.compile(r"Path found in .*seed 1\)")).wait_for(timeout=60_000)
    page.screenshot(path=artifacts / "04-replanned.png")
