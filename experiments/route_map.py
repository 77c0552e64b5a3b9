"""A search's route on its home's map, for a page or a paper: cut to the rooms the robot visited,
the route coloured by the room it is in, each room change marked and numbered in travel order,
axis labels in metres and the legend below the map (never over it)."""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from objsearch.agent.geometry import Point
from objsearch.experiments.plots import pyplot, save_figure

#: Metres of map shown around the visited rooms' viewpoints.
MARGIN_M = 0.7
#: A route step longer than this is a teleport between doors (drawn as a gap, not a walk).
JUMP_M = 0.5
#: Static labels closer than this to one already drawn are left out (they would overlap).
LABEL_GAP_M = 0.45


def rooms_in_order(navmap: Any, route: Sequence[Point]) -> list[tuple[str, int]]:
    """The rooms the route passes, in order, each with the index of the route point where the
    robot entered it (the first entry is the start room at index 0)."""
    out: list[tuple[str, int]] = []
    for i, p in enumerate(route):
        room = navmap.room_at(p.x, p.y)
        if not out or out[-1][0] != room:
            out.append((room, i))
    return out


def walked(navmap: Any, stops: Sequence[Point]) -> list[Point]:
    """Every point walked between the recorded stops (the map's shortest paths between them;
    two stops the map cannot join are drawn as a straight step)."""
    out = list(stops[:1])
    for a, b in itertools.pairwise(stops):
        try:
            walk = navmap.path(a, b)
        except (ValueError, KeyError):
            walk = [a, b]
        out += walk[1:]
    return out


def _stretches(navmap: Any, route: Sequence[Point]) -> list[tuple[str, list[Point]]]:
    """The route as one line per stretch walked inside one room, each with its room (a teleport
    between doors starts a new one)."""
    runs: list[tuple[str, list[Point]]] = []
    for a, b in itertools.pairwise(route):
        room = navmap.room_at(b.x, b.y)
        jump = math.hypot(b.x - a.x, b.y - a.y) > JUMP_M
        if runs and runs[-1][0] == room and not jump and runs[-1][1][-1] == a:
            runs[-1][1].append(b)
        else:
            runs.append((room, [b] if jump else [a, b]))
    return runs


def _legend_handles(start_label: str, target: str) -> list[Any]:
    """The legend's entries: the route, room changes, the start, the target, statics, containers."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    return [
        Line2D([], [], color="C0", lw=1.8, label="route, coloured by room"),
        Line2D([], [], color="w", marker="D", mec="k", mfc="0.7", ms=6,
               label="room change n (travel order)"),
        Line2D([], [], color="w", marker="s", mec="k", mfc="white", ms=7,
               label=f"start ({start_label})"),
        Line2D([], [], color="w", marker="*", mec="k", mfc="gold", ms=11, label=target),
        Patch(fill=False, ec="#7a7a7a", label="static object"),
        Patch(fill=False, ec="#1f4e79", label="container"),
    ]  # fmt: skip


def plot_route_map(
    ctx: Any,
    route: Sequence[Point],
    path: Path,
    *,
    title: str,
    start_label: str,
    target: str,
    targets_at: Sequence[tuple[float, float]] = (),
) -> list[Path]:
    """Draw ``route`` (dense: every point walked) over ``ctx``'s map into ``path`` (PNG, with SVG
    and PDF beside it); ``targets_at``: where the target objects are (stars)."""
    plt = pyplot()
    from matplotlib.patches import Rectangle

    navmap, semmap = ctx.navmap, ctx.semmap
    entered = rooms_in_order(navmap, route)
    visited = list(dict.fromkeys(r for r, _ in entered))
    rooms = {room.name: room for room in ctx.home.rooms}
    shown = [rooms[r] for r in visited if r in rooms]
    mine = [s for s in semmap.statics if navmap.room_at(s.loc.x, s.loc.y) in visited]
    xs = [p.x for room in shown for p in room.viewpoints] + [p.x for p in route]
    ys = [p.y for room in shown for p in room.viewpoints] + [p.y for p in route]
    for s in mine:  # the visited rooms' static objects whole, not cut at the map's edge
        (cx, cy, _), (sx, sy, _) = s.box.center, s.box.size
        xs += [cx - sx / 2, cx + sx / 2]
        ys += [cy - sy / 2, cy + sy / 2]
    x0, x1 = float(min(xs)) - MARGIN_M, float(max(xs)) + MARGIN_M
    # Room names go above the rooms: one more margin on top.
    y0, y1 = float(min(ys)) - MARGIN_M, float(max(ys)) + 2 * MARGIN_M
    width = min(9.0, max(4.0, 0.6 * (x1 - x0)))
    fig, ax = plt.subplots(figsize=(width + 2.6, width * (y1 - y0) / (x1 - x0) + 1.0))
    ax.grid(False)

    def inside(x: float, y: float) -> bool:
        return bool(x0 <= x <= x1 and y0 <= y <= y1)

    vps = [p for p in navmap.room_of if inside(p.x, p.y)]
    ax.scatter([p.x for p in vps], [p.y for p in vps], s=1.5, c="#d5d5d5", zorder=1, lw=0)
    colours = {r: f"C{i % 10}" for i, r in enumerate(visited)}
    placed: list[tuple[float, float]] = []
    for s in semmap.statics:
        (cx, cy, _), (sx, sy, _) = s.box.center, s.box.size
        if not inside(cx, cy):
            continue
        edge = "#1f4e79" if s.container else "#7a7a7a"
        ax.add_patch(
            Rectangle((cx - sx / 2, cy - sy / 2), sx, sy, fill=False, ec=edge, lw=0.7, zorder=2)
        )
        if all(math.hypot(cx - px, cy - py) >= LABEL_GAP_M for px, py in placed):
            placed.append((cx, cy))
            ax.text(cx, cy, s.cls, ha="center", va="center", fontsize=5.5, color=edge, zorder=2)
    for room in shown:
        cx = sum(p.x for p in room.viewpoints) / len(room.viewpoints)
        ax.text(cx, y1 - 0.15, room.name, ha="center", va="top", fontsize=9,
                weight="bold", color=colours[room.name], zorder=6)  # fmt: skip
    for room, pts in _stretches(navmap, route):
        ax.plot([p.x for p in pts], [p.y for p in pts], c=colours.get(room, "k"), lw=1.8, zorder=3)
    # Room changes: numbered in travel order where the robot entered each room.
    for n, (room, i) in enumerate(entered[1:], start=1):
        p = route[i]
        ax.scatter([p.x], [p.y], marker="D", s=28, c=colours.get(room, "k"), ec="k", lw=0.6,
                   zorder=5)  # fmt: skip
        ax.annotate(str(n), (p.x, p.y), xytext=(5, 5), textcoords="offset points", fontsize=7,
                    weight="bold", zorder=7,
                    bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.85})  # fmt: skip
    start = route[0]
    ax.scatter([start.x], [start.y], marker="s", s=50, c="white", ec="k", lw=1.2, zorder=5)
    stars = [(x, y) for x, y in targets_at if inside(x, y)]
    if stars:
        ax.scatter([x for x, _ in stars], [y for _, y in stars], marker="*", s=170, c="gold",
                   ec="k", zorder=5)  # fmt: skip
    order = " → ".join(r for r, _ in entered)
    ax.legend(
        handles=_legend_handles(start_label, target),
        loc="upper left",
        bbox_to_anchor=(1.01, 1.0),
        frameon=False,
    )
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"{title}\nrooms: {order}")
    return save_figure(fig, path)


__all__ = ["plot_route_map", "rooms_in_order", "walked"]
