"""Where per-bag tasks run: in this process, in local worker processes, or on a Ray cluster.

Ingest hands an :class:`Engine` one function and a list of inputs; the engine yields each
input's index with its result as results arrive. The function is the same whatever the engine
(:func:`objsearch.pipeline.bags.ingest.convert_bag`), and it returns its own errors as values,
so an engine only has to report what the function could not: a worker process that died or a
Ray task that was lost (:class:`TaskFailed`). Engines never touch the lake; the caller commits.

Ray is optional (``pip install 'objsearch[fleet]'``) and imported only by :class:`RayEngine`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar

from objsearch.pipeline.bags.errors import BagConfigError

T = TypeVar("T")
R = TypeVar("R")

ENGINES = ("local", "ray")


@dataclass(frozen=True, slots=True)
class TaskFailed:
    """A task that produced no result at all (its worker died, its node was lost)."""

    message: str


class Engine(Protocol):
    @property
    def in_process(self) -> bool:
        """True when tasks run in the caller's process (so they may draw a progress bar)."""

    def run(
        self, fn: Callable[[T], R], items: Sequence[T]
    ) -> Iterator[tuple[int, R | TaskFailed]]: ...


class InlineEngine:
    """One task after the other in this process."""

    in_process = True

    def run(self, fn: Callable[[T], R], items: Sequence[T]) -> Iterator[tuple[int, R | TaskFailed]]:
        for i, item in enumerate(items):
            yield i, fn(item)


@dataclass(frozen=True, slots=True)
class ProcessEngine:
    """``workers`` processes on this machine (``ProcessPoolExecutor``)."""

    workers: int
    in_process = False

    def run(self, fn: Callable[[T], R], items: Sequence[T]) -> Iterator[tuple[int, R | TaskFailed]]:
        with ProcessPoolExecutor(max_workers=self.workers) as pool:
            futures = {pool.submit(fn, item): i for i, item in enumerate(items)}
            for fut in as_completed(futures):
                try:
                    yield futures[fut], fut.result()
                except Exception as exc:  # boundary: the task raised, or its worker died
                    yield futures[fut], TaskFailed(f"task failed in a worker process: {exc!r}")


@dataclass(frozen=True, slots=True)
class RayEngine:
    """Tasks on Ray: the cluster at ``address``, or else a Ray instance already initialised in
    this process, or else a local instance of ``workers`` CPUs started (and stopped) here.

    Each task asks for one CPU. Ray retries a task once if its worker dies (a lost node), never
    for an error the task returns itself.
    """

    address: str | None = None
    workers: int = 1
    in_process = False

    def __post_init__(self) -> None:
        _import_ray()  # fail at construction, before any bag is touched

    def run(self, fn: Callable[[T], R], items: Sequence[T]) -> Iterator[tuple[int, R | TaskFailed]]:
        ray = _import_ray()
        RayError = ray.exceptions.RayError
        started = False
        if not ray.is_initialized():
            ray.init(
                address=self.address,
                num_cpus=None if self.address else self.workers,
                include_dashboard=False,
                log_to_driver=False,
            )
            started = True
        try:
            task = ray.remote(num_cpus=1, max_retries=1)(_call)
            index = {task.remote(fn, item): i for i, item in enumerate(items)}
            pending = list(index)
            while pending:
                done, pending = ray.wait(pending, num_returns=1)
                for ref in done:
                    try:
                        yield index[ref], ray.get(ref)
                    except RayError as exc:  # RayTaskError (the task raised), WorkerCrashedError …
                        cause = getattr(exc, "cause", None) or exc  # a RayTaskError wraps it
                        yield (
                            index[ref],
                            TaskFailed(f"Ray task failed: {type(cause).__name__}: {cause}"),
                        )
        finally:
            if started:
                ray.shutdown()


def _call(fn: Callable[[T], R], item: T) -> R:
    # ray.remote() of a class would make an actor; wrapping keeps any callable a plain task.
    return fn(item)


def _import_ray() -> Any:
    try:
        import ray
    except ImportError:
        raise BagConfigError(
            "--engine ray needs Ray, which is not installed: pip install 'objsearch[fleet]'"
        ) from None
    return ray


def make_engine(name: str, *, workers: int = 1, address: str | None = None) -> Engine:
    """The engine for ``--engine NAME [--workers N] [--address ADDR]``."""
    if workers < 1:
        raise BagConfigError("--workers must be at least 1")
    if name == "ray":
        return RayEngine(address=address, workers=workers)
    if name != "local":
        raise BagConfigError(f"unknown engine {name!r} (choose from {', '.join(ENGINES)})")
    if address is not None:
        raise BagConfigError("--address is for --engine ray")
    return InlineEngine() if workers == 1 else ProcessEngine(workers)
