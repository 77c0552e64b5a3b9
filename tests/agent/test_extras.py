"""torch is an optional extra: without it every command but ``map build`` runs, and ``map build``
says which extra it needs. "Without torch" is a fresh interpreter whose ``sys.modules`` maps
``torch`` to ``None``, which makes ``import torch`` fail as if it were not installed (the slow
test in tests/test_wheel.py does it for real, in a venv pip filled from the wheel alone)."""

from __future__ import annotations

import subprocess
import sys

import pytest

from objsearch.agent.extras import MissingExtraError, require, require_torch

NO_TORCH = "import sys\nsys.modules['torch'] = None\n"


def _without_torch(code: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", NO_TORCH + code], capture_output=True, text=True, check=False
    )


def test_require_names_the_extra_and_how_to_install_it() -> None:
    require("json", extra="none", purpose="reading", install="nothing")
    with pytest.raises(MissingExtraError) as raised:
        require("no_such_module_xyz", extra="xyz", purpose="objsearch frob", install="pip x")
    assert str(raised.value) == (
        "objsearch frob needs no_such_module_xyz, which is not installed (the optional extra "
        "'objsearch[xyz]'): pip x"
    )
    require_torch("this test")  # the dev venv has it


def test_map_build_without_torch_is_a_clear_error() -> None:
    proc = _without_torch(
        "from objsearch.cli import main\nsys.exit(main(['map', 'build', '--home', 'paper']))"
    )
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    assert proc.stderr.startswith("objsearch: error: objsearch map build needs torch")
    assert "pip install 'objsearch[torch]' --extra-index-url" in proc.stderr


def test_the_survey_and_a_search_need_no_torch() -> None:
    """``record --mapping-sweep`` plans its survey with agent/mapping.py, which imports torch
    only where views are fused; a search never imports it."""
    proc = _without_torch(
        "from objsearch.agent.mapping import survey_poses\n"
        "from objsearch.agent.session import load_context\n"
        "ctx = load_context('paper')\n"
        "assert survey_poses(ctx.navmap, ['kitchen'], 1)\n"
        "from objsearch.cli import main\n"
        "code = main(['search', 'Apple', '--start', 'kitchen-1', '--format', 'json'])\n"
        "assert sys.modules['torch'] is None\n"
        "sys.exit(code)\n"
    )
    assert proc.returncode == 0, proc.stderr
    assert '"success": true' in proc.stdout
