"""A reference on the Dynamic House Simulator that knows its generative model: ``bench dhs
--agents bound``.

:class:`BoundAgent` knows what its agents must learn — the scene's true placement priors (the
sampler's per-scene noisy priors graph, from which every object was placed when the scene was
drawn), the evolver's true move rates (each object's ``move_freq`` and the number of moves per
step, ``object_moves_per_step``) and its true move targets (the evolver's per-scene noisy priors,
``current_priors_graph``, keyed by the scene's own nodes) — and the task's query rule (half the
queries ask for an object moved in the step just taken). It knows no object's place: it
conditions on what an agent of the loop is shown, every attempt's outcome in this query and the
earlier ones of the scene (a miss: the target is not there; a find: it is), and at each place
tried the objects its observation model keeps (each dropped with probability
1 − ``observation_prob``, the draw its memory agents and ours make). It then tries the untried
places in decreasing posterior probability.

**In what sense it is a bound.** Within a query nothing moves, so with a unit cost per attempt
and the score min(attempts, ``max_attempts`` + 1), trying places in decreasing *exact*
posterior probability given the history minimises the expected score among all agents given
the same history (each partial sum of the probabilities tried is then the largest possible). It
is a floor on attempts only as far as its posterior is exact. This filter is exact for the
evolver's rules one object at a time, and approximate where the rules couple objects
(:class:`BoundAgent` lists each approximation): it tracks each object's place on its own (not
the joint), ignores the evolver's capacity rule (a move only to a piece of furniture holding
fewer than ``max_objects`` objects), takes an object moved twice in one step as moved once,
and places an object added during the scene as if it had been there from the scene's start. So
the figures it gives are a near-bound reference: an agent could beat it by at most what these
approximations cost, not by learning the model better.
"""

from __future__ import annotations

import random
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

#: The agent's name in ``bench dhs --agents`` and in tables.
BOUND = "bound"
#: What the bound can be run without, one piece at a time (``bound-no-<piece>``), to measure
#: what each is worth: the query rule (its move step then ignores which object was asked for),
#: the objects' own move rates (every object alike), the capacity rule (every piece of furniture
#: taken to have room).
ABLATIONS = ("query", "rates", "capacity")
#: The bound and its ablations, by name.
BOUND_AGENTS = (BOUND, *(f"{BOUND}-no-{piece}" for piece in ABLATIONS))
#: Half the queries ask for an object moved in the step just taken (``Task.pick_query``).
_PCT_QUERY_MOVED = 0.5

Vector = npt.NDArray[np.float64]


class BoundAgent:
    """The posterior filter (module doc), at the simulator's agent seam.

    Per object (keyed by ``description``, the identity its task and its agents use; two objects
    alike are one), a distribution over the scene's furniture. What it models per step, from
    the evolver's code (``PriorsSceneEvolver._move_objects``, ``get_move_target_probs``):
    ``m`` = ``object_moves_per_step`` moves, each of an object drawn in proportion to its
    ``move_freq`` (with replacement) to a piece of furniture other than its own drawn in
    proportion to the evolver's edge probabilities; when all those are 0, its draw under
    Python 3.8 takes the last option. An object whose priors node has one edge never moves. The
    query of the step: with probability ½ drawn by ``move_freq``, else uniformly from the moves
    of the step, so the step's move probability of each object is conditioned on whether it is
    the one asked for. Approximations: see the module doc.
    """

    def __init__(
        self, sampler: Any, evolver: Any, observation_prob: float, *, without: str | None = None
    ) -> None:
        from memsearch.graphs import NodeType

        if without is not None and without not in ABLATIONS:
            raise ValueError(f"without {without!r}: one of {', '.join(ABLATIONS)}")
        #: The piece of knowledge it runs without (:data:`ABLATIONS`), if any.
        self.without = without

        self._node_type = NodeType
        self.sampler = sampler
        self.evolver = evolver
        self.observation_prob = observation_prob
        self.scene: Any = None
        self.furniture: list[Any] = []
        self._column: dict[str, int] = {}
        self._in_room: list[bool] = []
        #: Per object (its ``unique_id``), its row; per description, the rows of its objects.
        self.rows: dict[str, int] = {}
        self.alike: dict[str, list[int]] = {}
        #: Row r, column f: P(object r is at furniture f | what was seen).
        self._belief: Vector = np.zeros((0, 0))
        self._targets: list[Vector] = []
        self._fallback: list[Vector] = []
        #: Per object category, per furniture category: its share of the sampler's draws there.
        self._shares: dict[str, dict[str, float]] = {}
        #: Steps the evolver took that the belief has not yet been carried through (applied
        #: when the query of the step is known).
        self.pending = 0
        self.target: str | None = None

    # -- its agent interface ------------------------------------------------------------------

    def transition_to_new_scene(self, scene: Any) -> None:
        """A new scene: every object at its placement prior, then the evolver's first step
        (its task evolves the scene once before the first query)."""
        self.scene = scene
        self.furniture = list(scene.scene_graph.get_nodes(self._node_type.FURNITURE))
        self._column = {f.unique_id: i for i, f in enumerate(self.furniture)}
        room = self._node_type.ROOM
        self._in_room = [any(p.type == room for p in f.get_parent_nodes()) for f in self.furniture]
        self.rows, self.alike, self._targets, self._fallback = {}, {}, [], []
        self._shares = {}
        self._belief = np.zeros((0, len(self.furniture)))
        self._track(scene.scene_graph.get_nodes_with_type(self._node_type.OBJECT))
        self.pending, self.target = 1, None

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
        options = [f for f in self.furniture if f.unique_id not in ignore_nodes_to_pred]
        if not options:
            return None
        # Its task finds any object of the description: P(one of them is at f).
        there = 1.0 - np.prod(1.0 - self._belief[self.alike[query.description]], axis=0)
        best, best_p = None, 0.0
        for node in options:  # ties: its node order
            p = float(there[self._column[node.unique_id]])
            if p > best_p:
                best, best_p = node, p
        return best if best is not None else random.choice(options)

    def receive_observation(self, node: Any) -> None:
        if self.target is None:
            return
        column = self._column[node.unique_id]
        children = sorted(node.get_children_nodes(), key=lambda n: n.description)
        objects = [c for c in children if c.type == self._node_type.OBJECT]
        self._track(objects, added=True)
        # Each child kept with probability observation_prob, in the order ours draws.
        kept = [self.rows[c.unique_id] for c in objects if random.random() <= self.observation_prob]
        miss = np.full(len(self.rows), 1.0 - self.observation_prob)
        miss[kept] = 1.0
        self._belief[:, column] *= miss
        self._belief[kept, :] = 0.0
        self._belief[kept, column] = 1.0
        # The attempt's outcome is exact (its task checks every child): an object of the
        # target's description is there or none is.
        alike = self.alike[self.target]
        if not any(c.description == self.target for c in objects):
            self._belief[alike, column] = 0.0
        elif len(alike) == 1:
            self._belief[alike, :] = 0.0
            self._belief[alike, column] = 1.0
        self._normalise()

    def step(self) -> None:
        """Its loop calls this after its task evolved the scene and drew the next query."""
        self.target = None
        self.pending += 1

    # -- the filter ----------------------------------------------------------------------------

    def _start(self, query: Any) -> None:
        self.target = query.description
        for _ in range(self.pending):
            self._evolve(query.unique_id)
        self.pending = 0
        self._track([query], added=True)

    def _evolve(self, queried: str) -> None:
        """One step of the evolver, conditioned on which object its task then asked for."""
        moves = int(self.evolver.object_moves_per_step)
        objects = self.scene.scene_graph.get_nodes_with_type(self._node_type.OBJECT)
        self._track(objects, added=True)
        # Its query draws by move_freq over every object; its moves, over those that can move.
        movable = [o for o in objects if self._fallback[self.rows[o.unique_id]].any()]
        rate = {
            o.unique_id: 1.0 if self.without == "rates" else float(o.move_freq) for o in objects
        }
        asked = sum(rate.values()) or 1.0
        total = sum(rate[o.unique_id] for o in movable) or 1.0
        if self.without == "capacity":
            free = np.ones(len(self.furniture))
        else:
            free = self._free([self.rows[o.unique_id] for o in objects])
        for o in movable:
            row = self.rows[o.unique_id]
            w = rate[o.unique_id] / total
            moved = 1.0 - (1.0 - w) ** moves if moves > 0 else 0.0
            if moved <= 0.0:
                continue
            # The query's likelihood if the object moved (k ≥ 1 of the m moves: E[k | k ≥ 1]
            # ≈ 1 + (m − 1) w) and if not.
            a = rate[o.unique_id] / asked
            if_moved = (1 - _PCT_QUERY_MOVED) * a + _PCT_QUERY_MOVED * (1 + (moves - 1) * w) / moves
            if_stayed = (1 - _PCT_QUERY_MOVED) * a
            if o.unique_id != queried:
                if_moved, if_stayed = 1.0 - if_moved, 1.0 - if_stayed
            if self.without == "query":
                if_moved = if_stayed = 1.0
            p = moved * if_moved / (moved * if_moved + (1.0 - moved) * if_stayed)
            b = self._belief[row]
            after = _moved(b, self._targets[row], self._fallback[row], free)
            self._belief[row] = (1.0 - p) * b + p * after
        self._normalise()

    def _free(self, rows: Sequence[int]) -> Vector:
        """P(a piece of furniture holds fewer than its cap of objects), from the objects'
        marginals taken as independent (Poisson-binomial, counts at the cap merged)."""
        cap = int(self.evolver.scene_max_objs_per_furniture)
        dist = np.zeros((len(self.furniture), cap + 1))
        dist[:, 0] = 1.0
        for row in rows:
            p = self._belief[row][:, None]
            shifted = np.zeros_like(dist)
            shifted[:, 1:] = dist[:, :-1]
            shifted[:, cap] += dist[:, cap]
            dist = dist * (1.0 - p) + shifted * p
        free: Vector = 1.0 - dist[:, cap]
        return free

    def _track(self, objects: Sequence[Any], *, added: bool = False) -> None:
        """Rows for objects not yet tracked: where they were put (the sampler's placement; the
        evolver's for an object ``added`` during the scene), where a move takes them."""
        rows = []
        for o in objects:
            if o.unique_id in self.rows:
                continue
            row = len(self.rows)
            self.rows[o.unique_id] = row
            self.alike.setdefault(o.description, []).append(row)
            rows.append(self._spawn(o) if added else self._placement(o))
            targets, fallback = self._move_targets(o)
            self._targets.append(targets)
            self._fallback.append(fallback)
        if rows:
            self._belief = np.vstack([self._belief, np.array(rows)])

    def _placement(self, obj: Any) -> Vector:
        """Where the sampler put an object of this category when it drew the scene: every piece
        of furniture of a room draws the same number of children, each in proportion to its
        priors edges (``PriorsSceneSampler.sample_children_nodes``), so P(at f) ∝ f's share for
        the category; a piece of furniture drawn as a child of another draws none."""
        graph = self.sampler.current_priors_graph
        share = self._shares.setdefault(obj.category, {})
        out = np.zeros(len(self.furniture))
        for i, f in enumerate(self.furniture):
            if not self._in_room[i]:
                continue
            if f.category not in share:
                node = graph.get_node_with_category(f.category)
                weights = {} if node is None else {e.node2: float(e.prob) for e in node.edges}
                total = sum(weights.values())
                mine = sum(v for n, v in weights.items() if n.category == obj.category)
                share[f.category] = mine / total if total > 0 else 0.0
            out[i] = share[f.category]
        return _unit(out)

    def _spawn(self, obj: Any) -> Vector:
        """Where the evolver adds an object of this category (``_add_objects``): each piece of
        furniture whose category's sampler priors node has it as a child, with the same chance."""
        graph = self.sampler.current_priors_graph
        out = np.zeros(len(self.furniture))
        for i, f in enumerate(self.furniture):
            node = graph.get_node_with_category(f.category)
            if node is not None and any(
                c.category == obj.category for c in node.get_children_nodes()
            ):
                out[i] = 1.0
        return _unit(out)

    def _move_targets(self, obj: Any) -> tuple[Vector, Vector]:
        """The evolver's weight of each piece of furniture as a move target of the object
        (``get_move_target_probs``: its edges in the evolver's priors; all 0 when it never
        moves), and the order of its options (1, 2, …; 0: none) for its draw from all-zero
        weights, which takes the last."""
        weights, order = np.zeros(len(self.furniture)), np.zeros(len(self.furniture))
        node = self.evolver.current_priors_graph.get_node_with_unique_id(obj.unique_id)
        if node is None or len(node.edges) == 1:
            return weights, order
        for rank, edge in enumerate(node.edges, start=1):
            column = self._column.get(edge.node1.unique_id)
            if column is not None:
                weights[column] += float(edge.prob)
                order[column] = rank
        return weights, order

    def _normalise(self) -> None:
        sums = self._belief.sum(axis=1, keepdims=True)
        uniform = 1.0 / max(1, self._belief.shape[1])
        self._belief = np.where(sums > 0, self._belief / np.where(sums > 0, sums, 1.0), uniform)


def bound_agent(name: str, sampler: Any, evolver: Any, observation_prob: float) -> BoundAgent:
    """The bound or one of its ablations by its name (:data:`BOUND_AGENTS`)."""
    if name not in BOUND_AGENTS:
        raise ValueError(f"{name!r}: one of {', '.join(BOUND_AGENTS)}")
    without = None if name == BOUND else name.removeprefix(f"{BOUND}-no-")
    return BoundAgent(sampler, evolver, observation_prob, without=without)


def _unit(v: Vector) -> Vector:
    total = float(v.sum())
    return v / total if total > 0 else np.full(len(v), 1.0 / max(1, len(v)))


def _moved(b: Vector, weights: Vector, order: Vector, free: Vector) -> Vector:
    """Where one move takes an object whose place is ``b`` (its ``_move_objects``): to a piece
    of furniture g ≠ f with room left (``free``: its probability) in proportion to its weight;
    when every target of positive weight is full, to the last free one of weight 0 in its
    options' order (its 3.8 draw); when none is free, nowhere."""
    v = weights * free
    left = v.sum() - v  # the expected weight of the targets other than f, per f
    positive = weights > 0
    log_full = np.where(positive, np.log(np.clip(1.0 - free, 1e-300, 1.0)), 0.0)
    # P(every positive-weight target but f is full), per f.
    all_full = np.exp(log_full.sum() - log_full)
    zero = (order > 0) & ~positive
    ranks = np.argsort(-np.where(zero, order, -1.0))  # zero-weight options, last first
    last = np.zeros_like(b)
    none_free = 1.0
    for g in ranks:
        if not zero[g]:
            break
        last[g] = free[g] * none_free
        none_free *= 1.0 - free[g]
    can = left > 0
    per = np.where(can, b * (1.0 - all_full) / np.where(can, left, 1.0), 0.0)
    to_zero = b * np.where(can, all_full, 1.0)
    out: Vector = v * (per.sum() - per) + last * (to_zero.sum() - to_zero)
    # What goes nowhere stays: the positive part when nothing is free, the rest of the fallback.
    out += to_zero * (1.0 - (last.sum() - last))
    return out
