"""The docs' generated figures: each block equals a fresh run of its command (the cheap ones here,
at most about 16 s each; ``make check-figures`` runs them all), and a stale block is caught."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from objsearch.experiments.figures import FIGURES, blocks, main, replace_blocks, run_figure

REPO = Path(__file__).resolve().parents[2]
DOCS = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]


def _doc_blocks() -> dict[str, tuple[Path, str]]:
    found: dict[str, tuple[Path, str]] = {}
    for path in DOCS:
        for name, body in blocks(path.read_text(encoding="utf-8")):
            assert name not in found, f"figure {name} in both {found[name][0]} and {path}"
            found[name] = (path, body)
    return found


def test_every_figure_is_in_the_docs_and_every_block_is_a_figure() -> None:
    found = _doc_blocks()
    assert sorted(found) == sorted(FIGURES)
    makefile = (REPO / "Makefile").read_text(encoding="utf-8")
    (figure_docs,) = [line for line in makefile.splitlines() if line.startswith("FIGURE_DOCS")]
    for path, _ in found.values():
        assert str(path.relative_to(REPO)) in figure_docs.split(), f"make figures misses {path}"


CHEAP = [name for name, figure in FIGURES.items() if figure.cheap]


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, str]]:
    """One scratch folder for the cheap figures, so the demo they read runs once."""
    return tmp_path_factory.mktemp("figures"), {}


def test_the_cheap_figures_are_the_ones_that_take_seconds() -> None:
    assert sorted(CHEAP) == ["demo", "map-build", "map-show", "replay", "replay-alpha"]


@pytest.mark.parametrize("name", CHEAP)
def test_cheap_figure_equals_a_fresh_run(name: str, runs: tuple[Path, dict[str, str]]) -> None:
    path, body = _doc_blocks()[name]
    fresh = run_figure(name, *runs)
    assert fresh == body, f"{path}: figure {name} is stale (run `make figures`); now:\n{fresh}"


def test_demo_headline_is_path_to_discovery_against_the_papers_figure() -> None:
    """One metric name: the paper's −25.27 % sits beside the path to discovery, never the full
    path, and the demo and bench paper report the same experiment."""
    found = _doc_blocks()
    demo = found["demo"][1]
    (headline,) = [line for line in demo.splitlines() if "the paper reports" in line]
    assert headline.startswith("path to discovery (the paper's metric)")
    (full,) = [line for line in demo.splitlines() if line.startswith("full path ")]
    assert "paper" not in full
    change = headline.split("(")[2].split(" %")[0]  # "-24.76"
    paper = found["bench-paper"][1]
    (wpl_all,) = [line for line in paper.splitlines() if line.startswith("wpl/all ")]
    assert f"{change}%" in wpl_all.replace(" ", "")


def test_the_bench_paper_block_is_what_its_command_prints() -> None:
    """The README's bench paper command runs the strategies its block shows, no more (without
    --strategies it ran all 17, about an hour, and the block kept three of them), and the block
    keeps every line the command prints but its timing (too slow a run for the suite: ``make
    check-figures`` compares the numbers)."""
    from objsearch.cli import build_parser
    from objsearch.cli_bench import _strategies

    path, body = _doc_blocks()["bench-paper"]
    command = body.split("`")[1]
    args = build_parser().parse_args(command.split()[1:])
    table1 = body.split("\nstrategy ", 1)[1].split("\n\n", 1)[0].splitlines()[1:]
    shown = [line.split()[0] for line in table1]
    assert _strategies(args.strategies, "all") == shown, path
    assert FIGURES["bench-paper"].keep == (r"^",)
    assert re.search(r"^\d+ searches; results in out/bench-paper$", body, re.MULTILINE)
    # The prose above the block: how many strategies the command runs without --strategies, and
    # that the block leaves out only the run time (its one substitution).
    from objsearch.experiments.strategies import STRATEGIES

    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text(encoding="utf-8")
    above = readme.split("<!-- figures:bench-paper -->", 1)[0].rstrip()
    prose = " ".join(above.split("\n\n")[-1].split())
    assert f"(`all`, {len(STRATEGIES)} of them)" in prose
    assert FIGURES["bench-paper"].subs == ((r" in [0-9.]+ s;", ";"),)
    assert "whole output but its run time" in prose


def test_a_stale_block_is_named_and_a_rewrite_fixes_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    doc = tmp_path / "doc.md"
    text = "before\n<!-- figures:map-show -->\nstale 0.25 m\n<!-- /figures -->\nafter\n"
    doc.write_text(text, encoding="utf-8")
    assert main(["--check", str(doc)]) == 1
    assert f"{doc}: map-show" in capsys.readouterr().err
    assert doc.read_text(encoding="utf-8") == text  # --check writes nothing
    assert main([str(doc)]) == 0
    rewritten = doc.read_text(encoding="utf-8")
    assert rewritten.startswith("before\n") and rewritten.endswith("<!-- /figures -->\nafter\n")
    assert "agreement with ALFRED interaction poses" in rewritten
    assert main(["--check", str(doc)]) == 0


def test_replace_blocks_keeps_what_is_outside_and_unnamed_blocks() -> None:
    text = "a\n<!-- figures:x -->\nold\n<!-- /figures -->\nb\n<!-- figures:y -->\nkeep\n<!-- /figures -->\n"
    new = replace_blocks(text, {"x": "new\n"})
    assert blocks(new) == [("x", "new\n"), ("y", "keep\n")]
    assert new.startswith("a\n") and "\nb\n" in new


def test_an_unknown_figure_is_a_clear_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    doc = tmp_path / "doc.md"
    doc.write_text("<!-- figures:nope -->\n<!-- /figures -->\n", encoding="utf-8")
    assert main([str(doc)]) == 2
    assert "objsearch: error: unknown figure(s) nope" in capsys.readouterr().err


def test_quoted_long_figures_are_on_the_pages_they_link() -> None:
    """The README quotes the long experiments (hours to rerun) from their generated pages: every
    number it quotes must be on a page the row links, so a regenerated page shows a stale quote
    (a presence check: a number that also stands elsewhere on the page passes)."""
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    checked = 0
    for row in readme.split("## What we measured", 1)[1].split("\n## ", 1)[0].splitlines():
        cells = [c.strip() for c in row.strip("|").split(" | ")]
        pages = re.findall(r"\(docs/(results[a-z0-9-]*\.md)", cells[-1]) if len(cells) == 3 else []
        if not pages:
            continue
        text = "".join((REPO / "docs" / p).read_text(encoding="utf-8") for p in pages)
        text = text.replace("−", "-")
        for number in re.findall(r"\d+(?:\.\d+)?", cells[1].replace("−", "-")):
            assert re.search(rf"(?<![\d.]){re.escape(number)}(?![\d])", text), (
                f"README quotes {number} ({cells[1]}), not on {', '.join(pages)}"
            )
        checked += 1
    assert checked >= 3
