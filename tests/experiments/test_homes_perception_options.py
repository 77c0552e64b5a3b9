"""experiments/homes.perception_options: the bench homes options that reproduce a run's detector."""

from __future__ import annotations

from dataclasses import replace

from objsearch.agent.detector_model import preset
from objsearch.experiments.homes import perception_options


def test_a_preset_run_needs_only_the_preset() -> None:
    assert perception_options(None) == {}
    assert perception_options(preset("realistic").params()) == {"perception": "realistic"}
    assert perception_options(preset("harsh").params()) == {"perception": "harsh"}


def test_a_run_with_another_confirmation_than_its_presets_names_it() -> None:
    # A realistic run spec without a confirmation is a score run (every run before the preset
    # confirmed by consistent): reproducing it needs --confirmation score, and no q.
    old = preset("realistic", "score").params()
    assert "confirmation" not in old
    assert perception_options(old) == {"perception": "realistic", "confirmation": "score"}
    harsh = preset("harsh", "consistent", fp_recurrence=0.3).params()
    assert perception_options(harsh) == {
        "perception": "harsh",
        "fp_recurrence": 0.3,
        "confirmation": "consistent",
    }
    overridden = preset("realistic", fp_per_image=0.5, fp_recurrence=0.3).params()
    assert perception_options(overridden) == {
        "perception": "realistic",
        "fp_per_image": 0.5,
        "fp_recurrence": 0.3,
    }


def test_a_run_that_does_not_look_again_names_its_relook() -> None:
    """The preset relooks; a run that did not (every run before the amendment of 21:12 UTC,
    whose spec names no relook) is reproduced with ``--relook off``."""
    assert perception_options(preset("realistic").params()) == {"perception": "realistic"}
    off = replace(preset("realistic"), relook="off")
    assert perception_options(off.params()) == {
        "perception": "realistic",
        "relook": "off",
    }


def test_a_run_that_pooled_its_stop_misses_names_it() -> None:
    """The preset counts misses per static; a run that pooled them (every run before the
    amendment of 23:03 UTC, whose spec names none) is reproduced with ``--stop-misses pooled``."""
    pooled = preset("realistic", stop_misses="pooled")
    assert perception_options(pooled.params()) == {
        "perception": "realistic",
        "stop_misses": "pooled",
    }
