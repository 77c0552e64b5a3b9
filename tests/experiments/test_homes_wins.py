"""bench homes' "< wpl" column: in how many (home, schedule) runs a strategy beats wpl, inspecting
as it does."""

from __future__ import annotations

from objsearch.experiments.homes import homes_summary, render
from objsearch.experiments.runner import Row


def _row(strategy: str, schedule: str, path: float, mode: str = "all") -> Row:
    return Row(
        "homes", "ithor-02", schedule, strategy, mode, 0, 1, "Cup", "s1", True, path, path / 2,
        f"t-{strategy}-{schedule}",
    )  # fmt: skip


def test_a_cover_run_counts_its_wins_against_wpl_cover() -> None:
    # --inspection cover names every strategy NAME+cover: the column said 0/0 for each.
    rows = [
        _row("wpl+cover", "habit-0", 10.0),
        _row("wpl+cover", "habit-1", 10.0),
        _row("global-belief+cover", "habit-0", 6.0),
        _row("global-belief+cover", "habit-1", 12.0),
        _row("wpl+cover", "habit-0", 11.0, "none"),
        _row("wpl+cover", "habit-1", 9.0, "none"),
    ]
    summary = homes_summary(rows)
    overall = summary["overall"]
    assert overall["global-belief+cover"]["runs_better_than_wpl"] == "1/2"
    assert overall["wpl+cover/none"]["runs_better_than_wpl"] == "1/2"
    assert overall["wpl+cover"]["runs_better_than_wpl"] == "0/2"
    assert summary["by_schedule"]["habit"]["global-belief+cover"]["runs_better_than_wpl"] == "1/2"
    summary.update(homes=["ithor-02"], seeds=[0, 1])
    line = next(s for s in render(summary).splitlines() if s.startswith("global-belief+cover "))
    assert line.split()[-1] == "1/2"


def test_a_single_run_is_not_counted_against_wpl_cover() -> None:
    rows = [
        _row("wpl", "habit-0", 10.0),
        _row("wpl+cover", "habit-0", 5.0),
        _row("ecost", "habit-0", 8.0),
        _row("ecost+cover", "habit-0", 6.0),
    ]
    overall = homes_summary(rows)["overall"]
    assert overall["ecost"]["runs_better_than_wpl"] == "1/1"  # 8 < wpl's 10
    assert overall["ecost+cover"]["runs_better_than_wpl"] == "0/1"  # 6 > wpl+cover's 5
