"""``audit --html``: the pages open in a real headless Chromium with no console error, every figure
drawn, tables that sort, and a page per task with its route, relation values and timeline."""

from __future__ import annotations

from pathlib import Path

from objsearch.agent.catalogue import STORE
from objsearch.cli import main
from objsearch.events import read_log
from objsearch.experiments.report_html import page_name
from objsearch.replay.audit import audit

from .browser import IMAGES_RENDERED, Browser, check_screenshot

LOG = Path(__file__).resolve().parents[1] / "replay" / "golden" / "sim-wpl-updates"

#: The index's "path m" column, top to bottom.
PATHS = """[...document.querySelectorAll("tbody tr")].map(r => Number(r.cells[4].dataset.v))"""


def test_audit_html_pages_render_in_chromium(tmp_path: Path) -> None:
    out = tmp_path / "audit"
    argv = ["audit", str(LOG), "--out", str(out), "--html", "--plots", "all", "--max-plots", "2"]
    assert main(argv) == 0
    tasks = audit(read_log(LOG, store=STORE)).tasks
    pages = [out / page_name(t.task_id) for t in tasks]
    assert all(p.is_file() for p in pages) and (out / "index.md").is_file()
    html = (out / "index.html").read_text()
    assert "<script src" not in html and "http" not in html.replace("http://www.w3.org", "")
    with Browser() as browser:
        browser.open(out / "index.html")
        assert browser.evaluate("document.querySelectorAll('tbody tr').length") == len(tasks)
        # Sorting: a click on "path m" orders the rows by it, a second click reverses them.
        browser.evaluate("document.querySelectorAll('th')[4].click()")
        paths = browser.evaluate(PATHS)
        assert paths == sorted(paths) and len(set(paths)) > 1
        browser.evaluate("document.querySelectorAll('th')[4].click()")
        assert browser.evaluate(PATHS) == sorted(paths, reverse=True)
        check_screenshot(browser.screenshot(tmp_path / "index.png"), 1280, 900)
        # A task with a route (the first two are drawn): figure, plans' relation values, timeline.
        browser.follow(f'tbody a[href="{pages[0].name}"]')
        assert browser.evaluate("location.pathname.split('/').pop()") == pages[0].name
        drawn = browser.evaluate(IMAGES_RENDERED)
        assert drawn == {"svgs": 1, "imgs": 0, "bad": []}
        text = browser.evaluate("document.body.innerText")
        for heading in ("Route", "Relation values behind each plan", "Timeline"):
            assert heading in text
        assert f"find {tasks[0].target} from {tasks[0].start}" in text
        assert "Rel" in text and "task started" in text
        check_screenshot(browser.screenshot(tmp_path / "task.png"), 1280, 900)
        # A task past --max-plots has no route and still loads cleanly.
        browser.open(pages[-1])
        assert browser.evaluate(IMAGES_RENDERED)["svgs"] == 0
        assert browser.errors == []
