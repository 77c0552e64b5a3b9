"""``objsearch demo``: the long-term schedule with scene-graph updates, against no updates."""

from __future__ import annotations

import csv
import math
import statistics
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from tqdm import tqdm

from objsearch.agent.outdir import claim
from objsearch.agent.scene_graph import UpdateMode
from objsearch.agent.session import load_context
from objsearch.agent.strategies import RunSpec
from objsearch.sim.longterm import TARGET_ORDER, Trial, run_schedule
from objsearch.sim.world import DEFAULT_CAMERA

SCENES = 10
STARTS = 8
#: What the demo writes into its --out folder.
OUTPUTS = ("log-all", "log-none", "path_lengths.csv", "path_length_per_scene.png")


def run_demo(
    *,
    out: Path,
    home: str = "paper",
    force: bool = False,
    progress: bool = True,
    baseline: bool = True,
    strategy: str = "wpl",  # the paper's method: the demo reproduces its experiment
    camera: str = DEFAULT_CAMERA,
    perception: Mapping[str, Any] | None = None,
    localisation: Mapping[str, Any] | None = None,
) -> int:
    modes = [UpdateMode.ALL, UpdateMode.NONE] if baseline else [UpdateMode.ALL]
    # --force replaces only what an earlier demo wrote here; anything else in --out is refused.
    with claim(out, command="demo", owns=OUTPUTS, force=force):
        return _run(out, home, modes, progress, strategy, camera, perception, localisation)


def _run(
    out: Path,
    home: str,
    modes: list[UpdateMode],
    progress: bool,
    strategy: str,
    camera: str,
    perception: Mapping[str, Any] | None = None,
    localisation: Mapping[str, Any] | None = None,
) -> int:
    ctx = load_context(home)
    params: dict[str, Any] = {"camera": camera}
    if perception:
        params["perception"] = dict(perception)  # docs/perception.md; absent: perfect
    if localisation:
        params["localisation"] = dict(localisation)  # docs/perception.md; absent: perfect
    spec = RunSpec.of(home, ctx.home.digest, strategy, seed=0, schedule="table2", params=params)
    results: dict[UpdateMode, list[Trial]] = {}
    total = SCENES * len(TARGET_ORDER) * STARTS * len(modes)
    done = [0]
    started = time.monotonic()
    in_pipe = progress and not sys.stderr.isatty()

    def searched(bar: Any) -> None:
        bar.update()
        done[0] += 1
        # Where no bar is drawn (a pipe, a log), a line at each tenth (DEVELOPERS.md, "Progress").
        if in_pipe and done[0] * 10 // total > (done[0] - 1) * 10 // total:
            elapsed = time.monotonic() - started
            print(
                f"demo: {done[0]} of {total} searches ({elapsed:.0f} s)",
                file=sys.stderr,
                flush=True,
            )

    # disable=None: drawn on a terminal only, never into a pipe or log (DEVELOPERS.md).
    with tqdm(
        total=total, disable=None if progress else True, file=sys.stderr, unit="search"
    ) as bar:
        for mode in modes:
            bar.set_description(f"updates={mode.value}")
            results[mode] = run_schedule(
                out / f"log-{mode.value}",
                spec.with_changes(update_mode=mode),
                on_trial=lambda _t: searched(bar),
            )
    write_csv(out / "path_lengths.csv", results)
    plot(out / "path_length_per_scene.png", results)
    print(render(results))
    print(f"\nevent logs: {', '.join(str(out / f'log-{m.value}') for m in modes)}")
    print(f"table: {out / 'path_lengths.csv'}   plot: {out / 'path_length_per_scene.png'}")
    return 0


def discovery(trial: Trial) -> float:
    """Metres to the detection of the target (the paper's metric); the whole path if not found."""
    return trial.path_length if trial.path_to_discovery is None else trial.path_to_discovery


def _mean(trials: Sequence[Trial], metric: Callable[[Trial], float] = discovery) -> float:
    return statistics.fmean(metric(t) for t in trials) if trials else math.nan


def _full(trial: Trial) -> float:
    return trial.path_length


def _change(base: float, new: float) -> str:
    return f"{base:.2f} m → {new:.2f} m ({100 * (new - base) / base:+.2f} %"


def render(results: dict[UpdateMode, list[Trial]]) -> str:
    updates = results[UpdateMode.ALL]
    scenes = sorted({t.scene for t in updates})
    lines = [
        "Mean path length to discovery (m; the paper's metric) over 8 starts, paper's method "
        "(WPL, α = 10) with updates of all pairs",
        f"{'target':18}" + "".join(f"{s:>7}" for s in scenes) + f"{'avg':>8}",
    ]
    for target in TARGET_ORDER:
        row = [t for t in updates if t.target == target]
        cells = [_mean([t for t in row if t.scene == s]) for s in scenes]
        lines.append(f"{target:18}" + "".join(f"{c:7.2f}" for c in cells) + f"{_mean(row):8.2f}")
    for mode, trials in results.items():
        cells = [_mean([t for t in trials if t.scene == s]) for s in scenes]
        label = "mean, " + ("updates" if mode is UpdateMode.ALL else "no update")
        lines.append(f"{label:18}" + "".join(f"{c:7.2f}" for c in cells) + f"{_mean(trials):8.2f}")
    success = sum(t.success for t in updates) / len(updates)
    oracle = statistics.fmean(t.oracle_length for t in updates)
    lines.append(
        f"success rate {success:.1%} of {len(updates)} searches with updates; mean oracle "
        f"{oracle:.2f} m (a full path: straight to the target's nearest viewpoint)"
    )
    if UpdateMode.NONE in results:
        base = results[UpdateMode.NONE]
        lines.append(
            "path to discovery (the paper's metric), no update → updates: "
            f"{_change(_mean(base), _mean(updates))}; the paper reports -25.27 %)"
        )
        lines.append(
            "full path (with the approach to the target's viewpoint), no update → updates: "
            f"{_change(_mean(base, _full), _mean(updates, _full))})"
        )
    return "\n".join(lines)


def write_csv(path: Path, results: dict[UpdateMode, list[Trial]]) -> None:
    with path.open("w", newline="", encoding="utf-8") as fh:
        writer = csv.writer(fh)
        writer.writerow(
            [
                "update_mode",
                "scene",
                "target",
                "start",
                "success",
                "path_length",
                "path_to_discovery",
                "oracle_length",
                "task_id",
            ]
        )
        for mode, trials in results.items():
            for t in trials:
                writer.writerow(
                    [
                        mode.value,
                        t.scene,
                        t.target,
                        t.start,
                        t.success,
                        f"{t.path_length:.4f}",
                        f"{discovery(t):.4f}",
                        f"{t.oracle_length:.4f}",
                        t.task_id,
                    ]
                )


def plot(path: Path, results: dict[UpdateMode, list[Trial]]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4), dpi=120)
    labels = {UpdateMode.ALL: "update all pairs", UpdateMode.NONE: "no update"}
    for mode, trials in results.items():
        scenes = sorted({t.scene for t in trials})
        ax.plot(
            scenes,
            [_mean([t for t in trials if t.scene == s]) for s in scenes],
            marker="o",
            label=labels.get(mode, mode.value),
        )
    oracle = results[UpdateMode.ALL]
    scenes = sorted({t.scene for t in oracle})
    ax.plot(
        scenes,
        [statistics.fmean(t.oracle_length for t in oracle if t.scene == s) for s in scenes],
        linestyle="--",
        color="grey",
        label="oracle (full path)",
    )
    ax.set_xlabel("scene (Table II)")
    ax.set_ylabel("mean path length to discovery (m)")
    ax.set_xticks(scenes)
    ax.set_title("Long-term search: path to discovery per scene (8 targets × 8 starts)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
