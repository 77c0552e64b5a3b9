"""The simulated robot's localisation: where it *believes* it is, against where it is.

Wheel odometry drifts as a random walk per metre driven (x, y and yaw); a localiser like AMCL
corrects it every :attr:`LocalisationModel.update_m` metres to its own estimate, whose error is
bounded (an AR(1) process with the localiser's RMS error as its stationary spread and a
correlation length in metres), and now and then jumps (a mis-convergence it recovers from at the
same rate). docs/perception.md (Localisation) gives every number and its source.

The robot's navigation works in the believed frame: it stops where it believes the goal
viewpoint is, so the simulator keeps the *believed* pose on the viewpoint graph (what the agent
reads from ``World.pose()`` and logs) and the *true* pose is the believed one less the error.
The camera sees from the true pose; a detection's position is reconstructed from the believed
one, so it is off by the pose error (:meth:`Localiser.reconstruct`).

Each motion step draws from its own generator, seeded from the run's seed and the step's index
in the run (never a global one), so a run replays exactly. A perfect model draws nothing.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from objsearch.agent.errors import ObjsearchError
from objsearch.agent.geometry import Pose, Vec3

if TYPE_CHECKING:
    from objsearch.agent.strategies import RunSpec

#: Keeps the localiser's draws apart from the detector's (seeded by run seed and view index).
_STREAM = 0x10CA1


@dataclass(frozen=True, slots=True)
class LocalisationModel:
    """A robot's localisation error model; every distance in metres, every angle in radians."""

    preset: str
    #: Odometry: standard deviation of the random walk's step per √metre driven.
    odom_xy_per_sqrt_m: float = 0.0
    odom_yaw_per_sqrt_m: float = 0.0
    #: The localiser corrects odometry (False: odometry alone, drifting without bound).
    localiser: bool = True
    #: Metres driven between two localiser updates (AMCL's ``update_min_d``).
    update_m: float = 0.2
    #: The localiser's stationary RMS error per axis, and its correlation length.
    rms_xy: float = 0.0
    rms_yaw: float = 0.0
    correlation_m: float = 2.0
    #: Mis-convergences: expected jumps per metre driven, and each jump's spread.
    jumps_per_m: float = 0.0
    jump_xy: float = 0.0
    jump_yaw: float = 0.0

    @property
    def perfect(self) -> bool:
        return (
            self.odom_xy_per_sqrt_m == 0.0
            and self.odom_yaw_per_sqrt_m == 0.0
            and self.rms_xy == 0.0
            and self.rms_yaw == 0.0
            and self.jumps_per_m == 0.0
        )

    def params(self) -> dict[str, Any]:
        """What ``run_started.params.localisation`` records: every parameter."""
        return asdict(self)


#: Presets by name (``--localisation``); the first is the default.
PRESETS = ("perfect", "realistic", "harsh")

_REALISTIC = LocalisationModel(
    "realistic",
    odom_xy_per_sqrt_m=0.03,
    odom_yaw_per_sqrt_m=math.radians(1.0),
    rms_xy=0.053,
    rms_yaw=math.radians(2.0),
    correlation_m=2.0,
    jumps_per_m=0.01,
    jump_xy=0.3,
    jump_yaw=math.radians(10.0),
)


def preset(name: str) -> LocalisationModel:
    """The model called ``name``: ``perfect`` (no error), ``realistic`` or ``harsh`` (twice the
    drift and the localiser's error, five times the jumps, larger ones)."""
    if name == "perfect":
        return LocalisationModel("perfect")
    if name == "realistic":
        return _REALISTIC
    if name == "harsh":
        r = _REALISTIC
        return replace(
            r,
            preset="harsh",
            odom_xy_per_sqrt_m=2 * r.odom_xy_per_sqrt_m,
            odom_yaw_per_sqrt_m=2 * r.odom_yaw_per_sqrt_m,
            rms_xy=2 * r.rms_xy,
            rms_yaw=2 * r.rms_yaw,
            jumps_per_m=5 * r.jumps_per_m,
            jump_xy=0.5,
            jump_yaw=math.radians(20.0),
        )
    raise ObjsearchError(f"unknown localisation {name!r}; choose from {', '.join(PRESETS)}")


def localisation_model(spec: RunSpec) -> LocalisationModel:
    """The model a run spec records (``params.localisation``); none recorded: perfect."""
    recorded = spec.params.get("localisation")
    if not recorded:
        return preset("perfect")
    try:
        return LocalisationModel(**dict(recorded))
    except TypeError as exc:
        raise ObjsearchError(f"the run's localisation {recorded!r} is not a model: {exc}") from None


class Localiser:
    """One run's pose error, advanced by each metre the robot drives (shared by every search of
    the run, as the robot's own localiser is)."""

    def __init__(self, model: LocalisationModel, seed: int) -> None:
        self.model = model
        self.seed = seed
        self.steps = 0
        rng = np.random.default_rng([seed, _STREAM, 0])
        # The robot starts localised: the localiser's stationary error, no drift yet.
        start = rng.standard_normal(3)
        self._fix = (
            model.rms_xy * float(start[0]) if model.localiser else 0.0,
            model.rms_xy * float(start[1]) if model.localiser else 0.0,
            model.rms_yaw * float(start[2]) if model.localiser else 0.0,
        )
        self._drift = (0.0, 0.0, 0.0)
        self._since_update = 0.0
        self.jumps = 0

    def error(self) -> tuple[float, float, float]:
        """Believed minus true pose: (x, y, yaw)."""
        return (
            self._fix[0] + self._drift[0],
            self._fix[1] + self._drift[1],
            self._fix[2] + self._drift[2],
        )

    def advance(self, metres: float) -> None:
        """The robot drove ``metres``: odometry drifts; the localiser updates when due."""
        if metres <= 0.0:
            return  # a turn in place or a teleport between room entries: no odometry
        self.steps += 1
        m = self.model
        rng = np.random.default_rng([self.seed, _STREAM, self.steps])
        # Every draw is made whatever happens, so one step's draws never depend on another's.
        walk, fix, jump = rng.standard_normal(3), rng.standard_normal(3), rng.standard_normal(3)
        u = float(rng.random())
        root = math.sqrt(metres)
        dx, dy, dyaw = self._drift
        self._drift = (
            dx + m.odom_xy_per_sqrt_m * root * float(walk[0]),
            dy + m.odom_xy_per_sqrt_m * root * float(walk[1]),
            dyaw + m.odom_yaw_per_sqrt_m * root * float(walk[2]),
        )
        if not m.localiser:
            return
        self._since_update += metres
        if self._since_update < m.update_m:
            return
        # The update: the localiser's estimate absorbs the drift; its own error moves on as an
        # AR(1) process whose stationary spread is its RMS error.
        rho = math.exp(-self._since_update / m.correlation_m)
        keep, fresh = rho, math.sqrt(1.0 - rho * rho)
        ex, ey, eyaw = self._fix
        ex = keep * ex + fresh * m.rms_xy * float(fix[0])
        ey = keep * ey + fresh * m.rms_xy * float(fix[1])
        eyaw = keep * eyaw + fresh * m.rms_yaw * float(fix[2])
        if u < m.jumps_per_m * self._since_update:
            self.jumps += 1
            ex += m.jump_xy * float(jump[0])
            ey += m.jump_xy * float(jump[1])
            eyaw += m.jump_yaw * float(jump[2])
        self._fix = (ex, ey, eyaw)
        self._drift = (0.0, 0.0, 0.0)
        self._since_update = 0.0

    def true_pose(self, believed: Pose) -> Pose:
        """Where the robot is when it believes it is at ``believed``."""
        ex, ey, eyaw = self.error()
        return Pose(believed.x - ex, believed.y - ey, believed.yaw - eyaw)

    def reconstruct(self, position: Vec3, believed: Pose) -> Vec3:
        """An object at ``position`` (true map frame), as the robot places it: measured from its
        true pose, put into the map from its believed pose ``believed``."""
        ex, ey, eyaw = self.error()
        tx, ty = believed.x - ex, believed.y - ey
        rx, ry = position[0] - tx, position[1] - ty
        c, s = math.cos(eyaw), math.sin(eyaw)
        return (believed.x + c * rx - s * ry, believed.y + s * rx + c * ry, position[2])


def with_localisation(
    spec: RunSpec, model: LocalisationModel | None = None
) -> tuple[RunSpec, Localiser | None]:
    """The spec with ``model`` recorded (``params.localisation``; given none, the one it already
    records), and the localiser that samples it for the run, None for a perfect one. A perfect
    model is not recorded, so a run without pose error writes the log it always did."""
    chosen = model if model is not None else localisation_model(spec)
    params = {k: v for k, v in spec.params.items() if k != "localisation"}
    if chosen.perfect:
        return spec.with_changes(params=params), None
    spec = spec.with_changes(params={**params, "localisation": chosen.params()})
    return spec, Localiser(chosen, spec.seed)
