"""The Dynamic House Simulator's learned agents, trained and run here on a CPU
(objsearch.experiments.dhs_sgm).

The CLI's errors are tested everywhere; the shim needs torch and spaCy (the extra ``dhs``); the
check of the re-uploaded text model needs it installed; training and running one of its learned
agents need the checkout too (``$OBJSEARCH_DHS_SOURCE``), and are skipped without them.
"""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path

import pytest

from devtools.cli_process import run_cli
from objsearch.agent.errors import ObjsearchError
from objsearch.experiments import dhs, dhs_sgm


def test_a_learned_agent_without_its_trained_model_is_a_clear_error(tmp_path: Path) -> None:
    done = run_cli("bench", "dhs", "--source", str(tmp_path), "--agents", "sgm_gcn")
    assert done.returncode == 2, done.stderr
    assert "objsearch: error:" in done.stderr and "Traceback" not in done.stderr
    assert "--agents sgm_gcn needs its trained model: pass --sgm-outputs DIR" in done.stderr

    outputs = tmp_path / "outputs"
    outputs.mkdir()
    done = run_cli(
        "bench",
        "dhs",
        "--source",
        str(tmp_path),
        "--agents",
        "sgm_gcn,belief",
        "--sgm-outputs",
        str(outputs),
    )
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr
    for experiment in dhs.EXPERIMENTS:
        assert f"{outputs}/{experiment}/models/gcn.pt" in done.stderr


def test_sgm_outputs_without_a_learned_agent_is_refused(tmp_path: Path) -> None:
    done = run_cli(
        "bench",
        "dhs",
        "--source",
        str(tmp_path),
        "--agents",
        "belief",
        "--sgm-outputs",
        str(tmp_path),
    )
    assert done.returncode == 2, done.stderr
    assert "--sgm-outputs is for its learned agents" in done.stderr


def test_an_unknown_learned_agent_is_refused_by_name() -> None:
    with pytest.raises(ObjsearchError, match="not one of its learned agents"):
        dhs_sgm.model_name("sgm_transformer")
    assert [dhs_sgm.model_name(a) for a in dhs.SGM_AGENTS] == ["mlp", "gcn", "heat", "hgt", "han"]


def test_training_refuses_a_checkout_whose_training_files_differ(tmp_path: Path) -> None:
    (tmp_path / "scripts").mkdir()
    (tmp_path / "scripts" / "train.py").write_text("# not theirs\n")
    with pytest.raises(ObjsearchError, match=r"scripts/train\.py, memsearch/running\.py"):
        dhs_sgm.verify_training_files(tmp_path)


def test_its_overrides_point_its_model_config_and_log_path_at_the_trained_weights(
    tmp_path: Path,
) -> None:
    assert dhs_sgm.sgm_overrides("sgm_heat", tmp_path) == [
        "model=heat",
        f"log_path={tmp_path.resolve()}",
    ]
    assert dhs_sgm.weights_path(tmp_path, "small_scenes", "sgm_gcn") == (
        tmp_path / "small_scenes" / "models" / "gcn.pt"
    )


def test_while_its_code_runs_cuda_keeps_tensors_and_modules_on_the_cpu() -> None:
    torch = pytest.importorskip("torch")
    pytest.importorskip("spacy")
    if importlib.util.find_spec(dhs_sgm.TEXT_MODEL_MODULE) is None:
        pytest.skip(f"{dhs_sgm.TEXT_MODEL_PACKAGE} is not installed (make dhs)")
    if torch.cuda.is_available():
        pytest.skip("a GPU is here: .cuda() would move the tensor outside the shim too")
    tensor, module = torch.ones(3), torch.nn.Linear(2, 1)
    with pytest.raises((AssertionError, RuntimeError)):
        tensor.cuda()  # no GPU: torch refuses, as its code did here before the shim
    with dhs_sgm.cpu_and_text_model():
        assert tensor.cuda() is tensor and tensor.device.type == "cpu"
        assert module.cuda() is module
    with pytest.raises((AssertionError, RuntimeError)):
        tensor.cuda()


def test_the_reuploaded_text_model_is_spacys_published_en_core_web_sm() -> None:
    pytest.importorskip("spacy")
    if importlib.util.find_spec(dhs_sgm.TEXT_MODEL_MODULE) is None:
        pytest.skip(f"{dhs_sgm.TEXT_MODEL_PACKAGE} is not installed (make dhs)")
    check = dhs_sgm.check_text_model()
    assert check["meta"] == dict(dhs_sgm.PUBLISHED_META)
    # Its featurizer reads token.vector: with no static vectors, the 96-wide tok2vec tensor
    # (its NodeFeaturizer counts 96 for it), the same for the same label every time.
    assert check["width"] == 96 and check["deterministic"]
    assert all(4.0 < norm < 9.0 for norm in check["norms"].values())


def _source() -> Path:
    source = os.environ.get(dhs.SOURCE_ENV)
    if not source:
        pytest.skip(f"no checkout of the simulator (${dhs.SOURCE_ENV})")
    for module in ("hydra", "gym", "torch_geometric", "spacy", "tensorboardX"):
        if importlib.util.find_spec(module) is None:
            pytest.skip(f"the simulator's dependency {module} is not installed (make dhs)")
    if importlib.util.find_spec(dhs_sgm.TEXT_MODEL_MODULE) is None:
        pytest.skip(f"{dhs_sgm.TEXT_MODEL_PACKAGE} is not installed (make dhs)")
    return dhs.verify_source(source)


@pytest.mark.slow
def test_its_learned_agent_trains_on_a_tiny_schedule_and_runs_by_its_rules(
    tmp_path: Path,
) -> None:
    source = _source()
    # Its own scripts, one epoch over 40 collected graphs: a minute, not the paper's schedule.
    weights = dhs_sgm.train(
        source,
        tmp_path,
        experiment="small_scenes",
        agent="sgm_gcn",
        train_steps=40,
        test_steps=20,
        epochs=1,
    )
    assert weights == tmp_path / "outputs" / "small_scenes" / "models" / "gcn.pt"
    assert weights.stat().st_size > 0
    job = dhs.DhsJob(
        str(source), "small_scenes", "sgm_gcn", 0, 20, 20, sgm_outputs=str(tmp_path / "outputs")
    )
    run = dhs.run_agent(job)
    assert run.crash is None and len(run.queries) == 20
    for q in run.queries:
        assert 1 <= q.attempts <= run.max_attempts + 1
        assert q.found == (q.attempts <= run.max_attempts)
