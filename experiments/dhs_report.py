"""``bench dhs``'s summary and tables: its metrics per experiment and agent, ours against each of
its agents paired by seed with a 95 % t interval, the targets (:mod:`objsearch.experiments.dhs`)."""

from __future__ import annotations

import math
import statistics
from collections.abc import Mapping, Sequence
from typing import Any

from objsearch.experiments.dhs_adapter import PINNED_COMMIT
from objsearch.experiments.dhs_bound import BOUND, BOUND_AGENTS
from objsearch.experiments.dhs_records import DISPLAY, OURS, AgentRun


def _spread(values: Sequence[float]) -> dict[str, float]:
    return {
        "median": statistics.median(values),
        "min": min(values),
        "max": max(values),
        "mean": statistics.fmean(values),
    }


def _mean(values: Sequence[float | None]) -> float | None:
    """The mean of the seeds that have one (None when none has: every run crashed at once)."""
    have = [v for v in values if v is not None]
    return statistics.fmean(have) if have else None


def _rounded(value: float | None) -> float | None:
    return None if value is None else round(value, 4)


def summarise(runs: Sequence[AgentRun]) -> dict[str, Any]:
    """Per experiment and agent: its metrics per seed, their mean over the seeds that answered a
    query, and the targets. A run whose code raised before any query has None per seed and is
    named in ``crashes``; an agent none of whose runs answered one has None metrics."""
    by: dict[str, dict[str, list[AgentRun]]] = {}
    for r in runs:
        by.setdefault(r.experiment, {}).setdefault(r.agent, []).append(r)
    experiments: dict[str, Any] = {}
    for experiment, agents in by.items():
        rows = {}
        for agent, rs in agents.items():
            rs = sorted(rs, key=lambda r: r.seed)
            rows[agent] = {
                "seeds": [r.seed for r in rs],
                "queries": sum(len(r.queries) for r in rs),
                "attempts": _mean([r.mean_attempts for r in rs]),
                "attempts_per_seed": [_rounded(r.mean_attempts) for r in rs],
                "found": _mean([r.found for r in rs]),
                "found_per_seed": [_rounded(r.found) for r in rs],
                "cost": _mean([r.mean_cost for r in rs]),
                "elapsed_s": round(math.fsum(r.elapsed_s for r in rs), 1),
                "crashes": [f"seed {r.seed}: {r.crash}" for r in rs if r.crash],
            }
        experiments[experiment] = {
            "agents": rows,
            "targets": _targets(rows),
            "paired": _paired(agents),
        }
        if BOUND in rows:
            experiments[experiment]["from_bound"] = from_bound(rows)
    return {"pinned_commit": PINNED_COMMIT, "experiments": experiments}


#: Two-sided 95 % quantiles of Student's t by degrees of freedom (1-30); above 30, 1.96 would
#: be too narrow by under 4 %, so the 30's is used.
_T95 = (
    12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228,
    2.201, 2.179, 2.160, 2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086,
    2.080, 2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048, 2.045, 2.042,
)  # fmt: skip


def paired_ci(diffs: Sequence[float]) -> tuple[float, float] | None:
    """The 95 % t interval of the mean of paired differences (None below two pairs)."""
    n = len(diffs)
    if n < 2:
        return None
    mean = statistics.fmean(diffs)
    half = _T95[min(n - 1, len(_T95)) - 1] * statistics.stdev(diffs) / math.sqrt(n)
    return (mean - half, mean + half)


def _paired(agents: Mapping[str, Sequence[AgentRun]]) -> dict[str, Any]:
    """Per agent of its: ours − its mean attempts, seed by seed (the seeds both answered), their
    mean and 95 % t interval. A seed is the pair: after the first query the two meet different
    scenes (each draws from the one random stream), so queries do not pair."""
    if OURS not in agents:
        return {}
    ours = {r.seed: r.mean_attempts for r in agents[OURS] if r.mean_attempts is not None}
    out: dict[str, Any] = {}
    for agent, rs in agents.items():
        if agent == OURS or agent in BOUND_AGENTS:  # no agents of its: from_bound
            continue
        theirs = {r.seed: r.mean_attempts for r in rs if r.mean_attempts is not None}
        seeds = sorted(ours.keys() & theirs.keys())
        diffs = [ours[s] - theirs[s] for s in seeds]
        out[agent] = _differences(seeds, diffs)
    return out


def from_bound(rows: Mapping[str, Mapping[str, Any]]) -> dict[str, Any]:
    """Per agent: its mean attempts − the bound's, seed by seed (the seeds both answered), their
    mean and 95 % t interval: how many more attempts it needs than the reference that knows the
    simulator's model (:mod:`objsearch.experiments.dhs_bound`)."""
    bound = _per_seed(rows[BOUND])
    out: dict[str, Any] = {}
    for agent, row in rows.items():
        if agent == BOUND:
            continue
        mine = _per_seed(row)
        seeds = sorted(mine.keys() & bound.keys())
        diffs = [mine[s] - bound[s] for s in seeds]
        out[agent] = _differences(seeds, diffs)
    return out


def _differences(seeds: list[int], diffs: list[float]) -> dict[str, Any]:
    """Per-seed differences as the tables print them: each, their mean and 95 % t interval."""
    ci = paired_ci(diffs)
    return {
        "seeds": seeds,
        "diffs": [round(d, 4) for d in diffs],
        "mean": _rounded(statistics.fmean(diffs)) if diffs else None,
        "ci95": None if ci is None else [round(ci[0], 4), round(ci[1], 4)],
    }


def _per_seed(row: Mapping[str, Any]) -> dict[int, float]:
    return {
        int(s): float(v)
        for s, v in zip(row["seeds"], row["attempts_per_seed"], strict=True)
        if v is not None
    }


def _targets(rows: Mapping[str, Mapping[str, Any]]) -> dict[str, Any] | None:
    """Fewer attempts than frequentist and myopic, and at least half the gap from the better of
    them to the oracle closed (the better of its two oracles when both ran)."""
    rows = {a: row for a, row in rows.items() if row["attempts"] is not None}  # not all crashed
    need = {OURS, "frequentist", "memorization"}
    oracles = [a for a in ("upper_bound", "oracle_upper_bound") if a in rows]
    if not need <= rows.keys() or not oracles:
        return None
    ours = rows[OURS]["attempts"]
    baseline_agent = min(("frequentist", "memorization"), key=lambda a: rows[a]["attempts"])
    baseline = rows[baseline_agent]["attempts"]
    oracle_agent = min(oracles, key=lambda a: rows[a]["attempts"])
    oracle = rows[oracle_agent]["attempts"]
    gap = baseline - oracle
    closed = (baseline - ours) / gap if gap > 0 else None
    return {
        "better_baseline": baseline_agent,
        "oracle": oracle_agent,
        "beats_frequentist_and_myopic": ours < baseline,
        # None when its oracle needs no fewer attempts than the better baseline: no gap.
        "gap_closed": closed,
        "half_gap_closed": closed is not None and closed >= 0.5,
        "beats_oracle": ours < oracle,
        "attempts": {"ours": ours, "baseline": baseline, "oracle": oracle},
    }


def render(summary: Mapping[str, Any]) -> str:
    """Its metrics per experiment config and agent, and the targets."""
    lines = [f"Dynamic House Simulator at {summary['pinned_commit'][:12]}, find-object task"]
    for experiment, block in summary["experiments"].items():
        lines.append("")
        rows = block["agents"]
        seeds = next(iter(rows.values()))["seeds"]
        lines.append(f"{experiment} (seeds {','.join(map(str, seeds))})")
        # Names longer than the column (the bound's ablations) widen it.
        width = max(14, *(len(DISPLAY.get(agent, agent)) for agent in rows))
        lines.append(
            f"  {'agent':<{width}} {'attempts':>9} {'found':>7} {'cost':>7} {'queries':>8}  "
            "attempts per seed"
        )
        crashes = []
        # Agents whose every run crashed at once come last, with no metrics.
        ranked = sorted(
            rows.items(),
            key=lambda kv: (kv[1]["attempts"] is None, kv[1]["attempts"] or 0),
        )
        for agent, row in ranked:
            name = DISPLAY.get(agent, agent)
            per_seed = " ".join(
                "crashed" if v is None else f"{v:.2f}" for v in row["attempts_per_seed"]
            )
            if row["attempts"] is None:
                metrics = f"{'crashed':>9} {'-':>7} {'-':>7}"
            else:
                metrics = f"{row['attempts']:>9.3f} {row['found']:>7.1%} {row['cost']:>7.2f}"
            lines.append(f"  {name:<{width}} {metrics} {row['queries']:>8}  {per_seed}")
            crashes += [f"  {name} {crash}" for crash in row["crashes"]]
        if crashes:
            lines.append("  runs its code ended by raising (their queries so far count):")
            lines += crashes
        targets = block["targets"]
        if targets:
            lines.append("  " + _verdict(targets))
        lines += _paired_lines(block.get("paired", {}))
        lines += _from_bound_lines(block.get("from_bound", {}), width)
    return "\n".join(lines)


def _from_bound_lines(gaps: Mapping[str, Any], width: int = 14) -> list[str]:
    """Each agent − the bound, seed by seed, with the 95 % t interval."""
    header = "  from the bound, each − bound (attempts it needs more), 95 % t CI:"
    return _difference_lines(gaps, header, width, judged=False)


def _paired_lines(paired: Mapping[str, Any]) -> list[str]:
    """Ours − each of its agents, seed by seed, with the 95 % t interval and what it says."""
    header = "  paired by seed, ours − its (attempts; below 0: ours needs fewer), 95 % t CI:"
    return _difference_lines(paired, header, 14, judged=True)


def _difference_lines(
    differences: Mapping[str, Any], header: str, width: int, *, judged: bool
) -> list[str]:
    """One line per agent of :func:`_differences`' summaries, smallest mean first; ``judged``
    adds what the interval says of ours against it."""
    if not differences:
        return []
    lines = [header]
    ordered = sorted(differences.items(), key=lambda kv: (kv[1]["mean"] is None, kv[1]["mean"]))
    for agent, p in ordered:
        name = DISPLAY.get(agent, agent)
        if p["mean"] is None:
            lines.append(f"    {name:<{width}} no seed both answered")
            continue
        diffs = " ".join(f"{d:+.3f}" for d in p["diffs"])
        ci, verdict = "", "one seed: no interval"
        if p["ci95"] is not None:
            lo, hi = p["ci95"]
            ci = f" [{lo:+.3f}, {hi:+.3f}]"
            verdict = "ours ahead" if hi < 0 else "ours behind" if lo > 0 else "CI includes 0"
        said = f"  {verdict}" if judged else ""
        lines.append(
            f"    {name:<{width}} {p['mean']:+.3f}{ci}{said}  ({len(p['seeds'])} seeds: {diffs})"
        )
    return lines


def _verdict(targets: Mapping[str, Any]) -> str:
    base = DISPLAY.get(targets["better_baseline"], targets["better_baseline"])
    oracle = DISPLAY.get(targets["oracle"], targets["oracle"])
    beats = "yes" if targets["beats_frequentist_and_myopic"] else "NO"
    closed = targets["gap_closed"]
    if closed is None:
        gap = f"no gap to close: its {oracle} needs no fewer attempts than {base}; ours " + (
            "needs fewer than its oracle too" if targets["beats_oracle"] else "does not beat it"
        )
    else:
        met = "met" if targets["half_gap_closed"] else "NOT met"
        a = targets["attempts"]
        gap = (
            f"gap from {base} ({a['baseline']:.3f}) to {oracle} ({a['oracle']:.3f}): "
            f"{a['baseline'] - a['oracle']:.3f} attempts, closed {closed:.0%} "
            f"(target ≥ 50 %: {met})"
        )
        if targets["beats_oracle"]:
            gap += "; ours needs fewer attempts than its oracle"
    return f"targets: fewer attempts than frequentist and myopic: {beats}; {gap}"
