"""The split of the simulator's queries by what happened to their object
(objsearch.experiments.dhs_changes): what needs no checkout of the simulator."""

from __future__ import annotations

from objsearch.experiments import dhs_changes


def test_an_agent_name_may_carry_our_agents_place_classes() -> None:
    plain = dhs_changes.job("/src", "large_scenes", "bayesian", 3, 100)
    assert (plain.agent, plain.seed, plain.steps, plain.furniture_key) == (
        "bayesian",
        3,
        100,
        "category",
    )
    labelled = dhs_changes.job("/src", "large_scenes", "belief@label", 0, 100)
    assert (labelled.agent, labelled.furniture_key) == ("belief", "label")


def test_the_first_agent_is_paired_with_each_other_seed_by_seed() -> None:
    text = dhs_changes.paired(
        {
            "belief": {0: 4.0, 1: 4.1, 2: 4.2},
            "belief@label": {0: 4.2, 1: 4.4, 2: 4.3},
            "bayesian": {1: 4.0},
        }
    )
    line = next(x for x in text.splitlines() if "belief − belief@label" in x)
    assert "-0.200 [" in line and "3 seeds: -0.200 -0.300 -0.100" in line
    lone = next(x for x in text.splitlines() if "belief − bayesian" in x)
    assert "+0.100 (95 % t, 1 seeds: +0.100)" in lone


def test_kinds_are_tabled_with_their_share_attempts_and_found() -> None:
    rows = [
        dhs_changes.Scored("stayed", False, 1, True),
        dhs_changes.Scored("moved", True, 11, False),
        dhs_changes.Scored("moved", True, 3, True),
    ]
    text = dhs_changes.table({"belief": rows})
    moved = next(x for x in text.splitlines() if x.split()[1:2] == ["moved"])
    assert moved.split()[2:] == ["2", "66.7%", "7.000", "50.0%"]
    this_step = next(x for x in text.splitlines() if "moved this step" in x and "not" not in x)
    assert "2" in this_step.split()
