"""Between the Dynamic House Simulator's code and ours (:mod:`objsearch.experiments.dhs`): its
checkout at the pinned commit (:func:`verify_source`), its modules importable with Python 3.8's
``random.choices`` (:func:`_their_code`), its hydra configs (:func:`load_config`), and our belief
at its agent seam (:class:`BeliefAgent`, made by :func:`make_belief_agent`; what maps to what:
docs/results-dhs.md)."""

from __future__ import annotations

import bisect
import contextlib
import hashlib
import itertools
import logging
import random
import sys
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from objsearch.agent.belief import Place, PlaceBelief
from objsearch.agent.catalogue import (
    Detected,
    PlanarPose,
    Record,
    SceneGraphSeeded,
    SeedValue,
    Support,
    TaskEnded,
    TaskStarted,
    ViewTaken,
    encode,
)
from objsearch.agent.errors import ObjsearchError
from objsearch.experiments.checkout import checkout_root
from objsearch.experiments.dhs_records import FURNITURE_KEYS

#: The commit of ``andreykurenkov/modeling_env_dynamics`` the numbers are for (its last, 2023-05-30).
PINNED_COMMIT = "74e5f9d722469f2d1148fe131aa85dfb049da7cb"
#: Environment variable naming the checkout when ``--source`` is not given.
SOURCE_ENV = "OBJSEARCH_DHS_SOURCE"

#: SHA-256 of every file of the pinned commit that the adapter imports or reads (its modules,
#: configs and priors): a checkout that differs in any of them is refused.
PINNED_FILES: Mapping[str, str] = {
    "configs/agents/all.yaml": "0ac80d10965cd010431f2a265842d5001ce2701aa51ac490e8cd7cd7f45af2d4",
    "configs/agents/all_no_fuse.yaml": "bce7eaff10620b4d515bc1431610a8b2a348b4e5d7535f310a1b2f3511bbd943",
    "configs/agents/igridson_agents.yaml": "56ffa160de20aef56a7a55499a85d02693f41c120619b51a3ec32e7910568bc0",
    "configs/agents/non_psg.yaml": "29370f112cdccd48067e2201af34ca3517b19b1ff5c4438575f3679803fbf820",
    "configs/agents/psg.yaml": "61e67fc87a0ec1338b28009f2dd827f596fba34d616255adc4599926c0debe58",
    "configs/config.yaml": "28f4ab80ff93c026f3dcab1b354e4ae6d0efdacb12d9b1012526cfcf32c2baa5",
    "configs/data_gen/10k.yaml": "b235c8eed357a2832135209e95ef9a920172ad8415092b2c26476b81ef632119",
    "configs/data_gen/5k.yaml": "0560d09709d2dde746ae82b7d5f9cc685af93c9b43d4eaa2467b1b6a74e09b2d",
    "configs/experiment/add_remove_objs.yaml": "173db657a5122a2869da7df0311281b561beb5c10327c1b26fe4022f025914d7",
    "configs/experiment/agent_no_priors.yaml": "436dc5c3d7e4955d6086ed2ec4e235bb236819ae989985fbd0b5bcded507858b",
    "configs/experiment/agent_ok_priors.yaml": "4ad9c895d6923b3d8aa4753fcee034d925ed81db20f88656c2ca4520e22b2f10",
    "configs/experiment/example.yaml": "714f946e868688ea0f5dc4edca68444a76954edb4e32222345709cbe63ac8f85",
    "configs/experiment/large_scenes.yaml": "7cef42311e7fe17c225494a752a67a2d436fc6c6aaf4ec08ecde8ebc27bd4e5c",
    "configs/experiment/model_no_fuse.yaml": "0e388a3ad2943222ec1fcda9dda149e55f398f3bffd9724107e10d3fecb7fb8c",
    "configs/experiment/noisy_priors.yaml": "0e84294a2fb634ac37e8a831b614ebf54e9a06f84fb01417fa70acbf83679cbb",
    "configs/experiment/save_images.yaml": "5f3659c7cab5715c688cc617b47a87a29f3b7aef1905caede9195a8c15f1eb81",
    "configs/experiment/simulate_agents.yaml": "223eea17870b4572d4e132f94cdc95fa6d313974ea7c806ccddbc27a9eca61bf",
    "configs/experiment/small_scenes.yaml": "da79684d955a2546ee35035bc89ff55ed9cfef4bb2953f3317b4476a5ba12630",
    "configs/model/gcn.yaml": "5ee8da8994867dc52ee526e6440214d1d51d291fcc1996c6c53ca91258fa5475",
    "configs/model/gcn_no_fuse.yaml": "aee160145ab3b5d1b7cd53e2537bdd6b851ae399fd0dbeb4cf1a92d49a6c6752",
    "configs/model/han.yaml": "447438a74b38ea71d05dbcf21026342298b3b15ae0e9d0068ea38d7d6268421c",
    "configs/model/heat.yaml": "413d873d7350b26e3000599cd6e3150b01aeb32f76274f5f23d3a9063a3daa9c",
    "configs/model/heat_no_fuse.yaml": "1827152b3b06bd016449f0456de4efb85ad32140af37dc18a37787674ed42338",
    "configs/model/hgcn.yaml": "638b61ba65da80125c84d2bf1b359508f4f42f7b6638385266fb9fe5b73b80f2",
    "configs/model/hgt.yaml": "1bea59feed6c97a9441044a1923067467340da1da6b2d5bdb0e5903adacfc48e",
    "configs/model/mlp.yaml": "9b3df32aecf400a140b51389648fa5ca2a47742d66c3ddc4ba6cd4a5cf0a370a",
    "configs/model/recurrent_gcn.yaml": "4d85381b8ae51285475105a44e5344785de4a8b7d35720639c12fc4a6ba73786",
    "configs/scene_gen/igridson_scenes.yaml": "2ceac511ed935623cd287395d24b11518fd5e4b33bd265af245498af53c7fd7a",
    "configs/scene_gen/large_scenes.yaml": "4907b0fd4f780903db3021d995eabc1c0c59491aad14b66de590c1e235c02976",
    "configs/scene_gen/small_scenes.yaml": "d1aa20e4523edda18d98aa25ee01036e20e544ff8b458a127280ead31b42046d",
    "configs/task/find_object.yaml": "483ddf0a26a16a24e56953e884357d3a71cc0ab609a237b740269bbdb70493c9",
    "memsearch/__init__.py": "5333ff9bee4a7555098a4ca8d1ffdd54198a95fe86a45e8aa14f90bd254f7d0a",
    "memsearch/agents.py": "fb80c3e6c05a4d33584af5bf9fcb9c06ef03d7a3cc31ce6e13c595146342e289",
    "memsearch/dataset.py": "1013767897bd113030b524e85adf555239bcc8cdf805c5f6a9db37811a94a737",
    "memsearch/graphs.py": "a43ae4ded1073a80069fb7f3f70f368b4f06eb8cf05ca9ddc090f9a0ffe906bd",
    "memsearch/models.py": "7bda75505778d01e78fa5f984645893ce18b694854c37fe38fa4a40d79253fe6",
    "memsearch/scene.py": "692b0ad9b3945d1853618d2b17c4f2dcea2c95ea7d3ec8a220d5facb06a30204",
    "memsearch/tasks.py": "9b122e28aea4dc5f3246e53da336b98b224e49675747631df7ce7a946c5d097d",
    "memsearch/util.py": "e0c9a456c04da87418d4231c29aeba4e620519463d2162152373c999cfb1d7b2",
    "priors/coarse_prior_graph.pickle": "5dff7d15ad6bd4172f18ba02748e1b1852015704d95802ebd504e192650897f8",
    "priors/detailed_prior_graph.pickle": "5be488749aad1e07738899f836b3e502d26a119b311c732b3c044c1067cfa6ab",
    "priors/hardcoded_placement_probs.yaml": "f66aa81c2543a87dae9415bd98be187f022cc4e36ae2cae741c6f80c55aee3b2",
    "priors/object_metadata.yaml": "260ca8e1a9d6d3805c39b1b9841ed466e491b55ee194445beaf8521d0e15668c",
}


def verify_source(source: Path | str | None) -> Path:
    """The checkout, after checking every pinned file; raises :class:`ObjsearchError`."""
    root = checkout_root(
        source,
        SOURCE_ENV,
        command="bench dhs",
        repo="andreykurenkov/modeling_env_dynamics",
        commit=PINNED_COMMIT,
        doc="docs/results-dhs.md",
    )
    missing, changed = [], []
    for name, digest in PINNED_FILES.items():
        path = root / name
        if not path.is_file():
            missing.append(name)
        elif hashlib.sha256(path.read_bytes()).hexdigest() != digest:
            changed.append(name)
    if missing or changed:
        parts = []
        if missing:
            parts.append(f"missing {', '.join(missing[:5])}" + (" …" if len(missing) > 5 else ""))
        if changed:
            parts.append(f"changed {', '.join(changed[:5])}" + (" …" if len(changed) > 5 else ""))
        raise ObjsearchError(
            f"--source {root} is not modeling_env_dynamics at commit {PINNED_COMMIT[:12]}: "
            + "; ".join(parts)
        )
    return root


_CHOICES = random.choices


def _choices_py38(
    population: Sequence[Any],
    weights: Iterable[float] | None = None,
    *,
    cum_weights: Sequence[float] | None = None,
    k: int = 1,
) -> list[Any]:
    """``random.choices`` as Python 3.8 has it, the interpreter its code is written for
    (environment.yml: python=3.8). From 3.9 on, weights that sum to zero raise ValueError; 3.8
    drew from them as from any others (one ``random()``, bisected into the all-zero cumulative
    weights: the last option). Its evolver meets such weights (an object whose every move target
    has probability 0 in a scene's noisy priors), so under 3.9+ its published configs crash in
    the first scenes. Any other call is 3.11's, which draws exactly as 3.8's.
    """
    if cum_weights is None and weights is not None:
        cum_weights = list(itertools.accumulate(weights))
    if cum_weights is not None and len(cum_weights) == len(population) and population:
        total = cum_weights[-1] + 0.0
        if total <= 0.0:
            hi = len(population) - 1
            return [
                population[bisect.bisect(cum_weights, random.random() * total, 0, hi)]
                for _ in range(k)
            ]
    return _CHOICES(population, cum_weights=cum_weights, k=k)


@contextlib.contextmanager
def _their_code(root: Path) -> Iterator[None]:
    """Its modules importable, its relative paths (priors/) resolving as when its scripts run
    from the checkout, and Python 3.8's ``random.choices`` (:func:`_choices_py38`)."""
    path = str(root.resolve())
    sys.path.insert(0, path)
    random.choices = _choices_py38  # type: ignore[assignment]
    # Its evolver logs a warning each time it gives up moving an object (100 tries): thousands.
    logging.disable(logging.WARNING)
    try:
        with contextlib.chdir(root):
            yield
    finally:
        logging.disable(logging.NOTSET)
        random.choices = _CHOICES
        with contextlib.suppress(ValueError):
            sys.path.remove(path)


def _missing_dependency(error: ModuleNotFoundError) -> ObjsearchError:
    return ObjsearchError(
        f"the simulator's code needs {error.name!r}, not installed: pip install -e '.[dhs]' "
        "(make dhs) installs what it imports"
    )


def load_config(root: Path, experiment: str, overrides: Sequence[str] = ()) -> Any:
    """Its hydra config of ``experiment`` with its find-object task (``task=find_object``)."""
    try:
        from hydra import compose, initialize_config_dir
    except ModuleNotFoundError as error:
        raise _missing_dependency(error) from None
    if experiment not in _experiments(root):
        raise ObjsearchError(
            f"no experiment config {experiment!r} in {root}/configs/experiment "
            f"(known: {', '.join(sorted(_experiments(root)))})"
        )
    with initialize_config_dir(config_dir=str((root / "configs").resolve()), version_base=None):
        return compose(
            config_name="config",
            overrides=[f"experiment={experiment}", "task=find_object", *overrides],
        )


def _experiments(root: Path) -> set[str]:
    return {p.stem for p in (root / "configs" / "experiment").glob("*.yaml")}


@dataclass(frozen=True, slots=True)
class RecordEvent:
    """A record as the belief folds it, numbered: the events of searches no simulator of ours
    ran (this adapter's; the belief tests' hand-written logs)."""

    seq: int
    type: str
    payload: Mapping[str, Any]
    task_id: str | None = None

    @classmethod
    def of(cls, seq: int, record: Record, task_id: str | None = None) -> RecordEvent:
        return cls(seq, record.TYPE, encode(record), task_id)


def sighting(object_class: str, instance_id: str, static_id: str, static_class: str) -> Detected:
    """An accepted detection of ``object_class`` at a place (support ``at``), no geometry."""
    return Detected(
        object_class=object_class,
        instance_id=instance_id,
        mask_area=1.0,
        position=(0.0, 0.0, 0.0),
        accepted=True,
        support=Support(static_id=static_id, static_class=static_class, at=True),
        score=1.0,
        classes=(),
    )


class BeliefAgent:
    """Our belief at the simulator's agent seam (see the module doc for what maps to what)."""

    def __init__(
        self,
        priors_graph: Any,
        observation_prob: float,
        *,
        prior_strength: float,
        half_life_scenes: float,
        furniture_key: str = "category",
    ) -> None:
        from memsearch.graphs import NodeType

        if furniture_key not in FURNITURE_KEYS:
            raise ValueError(f"furniture_key {furniture_key!r}: one of {', '.join(FURNITURE_KEYS)}")
        #: What a place's class is: its ``category`` (default) or its ``label`` (before).
        self.furniture_key = furniture_key

        self._node_type = NodeType
        self.priors_graph = priors_graph
        self.observation_prob = observation_prob
        self.prior_strength = prior_strength
        self.half_life_scenes = half_life_scenes
        self.belief = PlaceBelief(prior_strength=prior_strength, half_life_scenes=half_life_scenes)
        self.seq = 0
        self.queries = 0
        self.target: str | None = None
        self.seen_target = False
        self.seeded: set[str] = set()
        self.labels: dict[str, str] = {}
        #: Rel₀ per object label in the current scene (its place classes are fixed per scene).
        self._rel0_of: dict[str, dict[str, float]] = {}
        self.scene: Any = None
        self.looks = 0
        #: Places looked at in the last query that ended.
        self.last_looks = 0

    # -- its agent interface ------------------------------------------------------------------

    def transition_to_new_scene(self, scene: Any) -> None:
        self.scene = scene
        self.belief = PlaceBelief(
            prior_strength=self.prior_strength, half_life_scenes=self.half_life_scenes
        )
        self.seeded, self.labels, self._rel0_of = set(), {}, {}
        self.target, self.queries = None, 0
        from memsearch.scene import get_edge_to_parent_node_by_type

        for node in scene.scene_graph.get_nodes(self._node_type.FURNITURE):
            edge, _ = get_edge_to_parent_node_by_type(node, self._node_type.ROOM)
            self.belief.places[node.unique_id] = Place(
                node.unique_id, self._class(node), edge.node1.description
            )
        self._seed(scene.scene_graph.get_nodes_with_type(self._node_type.OBJECT))

    def make_predictions(
        self,
        task_type: Any,
        scene: Any,
        query: Any,
        top_k: int = 3,
        ignore_nodes_to_pred: Sequence[str] = (),
    ) -> Any:
        if self.target is None:
            self._start(query)
        options = [
            n
            for n in scene.scene_graph.get_nodes(self._node_type.FURNITURE)
            if n.unique_id not in ignore_nodes_to_pred
        ]
        if not options:
            return None
        d = query.description
        best, best_p = None, 0.0
        for node in options:
            p = self.belief.instance_rel(d, node.unique_id, self._class(node))
            if p > best_p:
                best, best_p = node, p
        return best if best is not None else random.choice(options)

    def receive_observation(self, node: Any) -> None:
        if self.target is None:
            return
        self.looks += 1
        self._add(ViewTaken(pose=_ORIGIN, pitch=0.0, static_id=node.unique_id, reason="look"))
        children = sorted(node.get_children_nodes(), key=lambda n: n.description)
        kept = []
        for child in children:
            if random.random() > self.observation_prob:
                continue
            if child.type == self._node_type.OBJECT:
                kept.append(child)
        self._seed(kept)
        for child in kept:
            self._add(
                sighting(
                    child.description,
                    child.unique_id,
                    node.unique_id,
                    self._class(node),
                )
            )
            if child.description == self.target:
                self.seen_target = True

    def step(self) -> None:
        if self.target is not None:
            self._add(TaskEnded(target=self.target, success=self.seen_target, path_length=0.0))
            self.target, self.last_looks = None, self.looks

    # -- events ----------------------------------------------------------------------------------

    def _start(self, query: Any) -> None:
        self._seed([query])
        self.queries += 1
        self.target, self.seen_target, self.looks = query.description, False, 0
        self._add(
            TaskStarted(
                target=self.target,
                start="",
                pose=_ORIGIN,
                scene=self.queries,
                clock=None,
            )
        )

    def _seed(self, objects: Sequence[Any]) -> None:
        """Rel₀ of each object not yet seeded, from the priors graph (the whole seed again, as
        the belief takes one ``scene_graph_seeded``: objects appear as the scene evolves)."""
        new = [o for o in objects if o.description not in self.seeded]
        if not new:
            return
        for o in new:
            self.seeded.add(o.description)
            self.labels[o.description] = o.label
        values: list[SeedValue] = []
        for d in sorted(self.seeded):
            label = self.labels[d]
            rel = self._rel0_of.get(label)
            if rel is None:
                rel = self._rel0_of[label] = self._rel0(label)
            values.extend(SeedValue(dynamic=d, static=s, rel=v) for s, v in sorted(rel.items()))
        self._add(SceneGraphSeeded(source="dhs priors graph", values=tuple(values)))

    def _class(self, node: Any) -> str:
        return str(node.category if self.furniture_key == "category" else node.label)

    def _rel0(self, object_label: str) -> dict[str, float]:
        """Rel₀(object, place class) for the place classes of this scene, from its priors graph.

        By category (the default), as its Bayesian agent reads it (``init_dist_for_edge``): the
        edge from the furniture's category node (``chair-kitchen``, ``arm_chair-bedroom``) to a
        node of the object's label, the largest where several nodes carry the label (its
        Bayesian takes the first that has an edge: the same number in the configs measured).
        Its evolver draws moves from these category edges. Its coarse priors graph
        (``agent_ok_priors``) has categories without the room: there the category's first part.
        By label (before): the largest edge
        from any furniture node of that label, which merges a label's categories (its 42
        furniture categories carry 21 labels) and ranked the evolver's targets worse
        (docs/results-dhs.md, "Why its Bayesian led").
        """
        classes = {p.static_class for p in self.belief.places.values()}
        rel: dict[str, float] = {}
        if self.furniture_key == "label":
            for edge in self.priors_graph.get_edges_to(object_label, self._node_type.FURNITURE):
                label = edge.node1.label
                if label in classes and edge.prob > 0:
                    rel[label] = max(rel.get(label, 0.0), min(1.0, float(edge.prob)))
            return rel
        objects = self.priors_graph.get_nodes_with_label(object_label)
        for category in classes:
            # Its coarse priors (agent_ok_priors) name a category without its room
            # (``arm_chair`` for ``arm_chair-bedroom``): every detailed category has one.
            furniture = self.priors_graph.get_node_with_category(
                category
            ) or self.priors_graph.get_node_with_category(category.split("-")[0])
            if furniture is None:
                continue
            for obj in objects:
                edge = furniture.get_edge_to(obj)
                if edge is not None and edge.prob > 0:
                    rel[category] = max(rel.get(category, 0.0), min(1.0, float(edge.prob)))
        return rel

    def _add(self, record: Record) -> None:
        self.seq += 1
        self.belief.apply(RecordEvent.of(self.seq, record))


_ORIGIN = PlanarPose(x=0.0, y=0.0, yaw=0.0)


def make_belief_agent(cfg: Any, furniture_key: str = "category") -> BeliefAgent:
    """Our agent for its config: its priors graph of the agents' type, normalised as its
    ``make_agent`` does, and the belief's constants of the strategy ``ecost-belief``."""
    from memsearch.graphs import load_priors_graph

    from objsearch.agent.strategies import BELIEF

    priors_graph = load_priors_graph(cfg.agents.agent_priors_type)
    for node in priors_graph.nodes:  # as its make_agent does for every agent
        node.normalize_edges_to_me()
    assert BELIEF.prior_strength is not None and BELIEF.half_life_tasks is not None
    return BeliefAgent(
        priors_graph,
        float(cfg.agents.observation_prob),
        prior_strength=BELIEF.prior_strength,
        half_life_scenes=BELIEF.half_life_tasks,
        furniture_key=furniture_key,
    )
