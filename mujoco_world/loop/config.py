"""Settings of the closed loop (``RunConfig``), kept with every run record."""

from __future__ import annotations

from dataclasses import dataclass, field

from ethical_planner.validation import check, check_positive, parse_enum
from mujoco_world.loop.progress import StallConfig
from mujoco_world.loop.world import ObservationNoise
from mujoco_world.physics.control import ControlConfig
from mujoco_world.scenario.spec import PostCrashPolicy


@dataclass(frozen=True, slots=True)
class RunConfig:
    """Settings of the closed loop.

    Attributes:
        replan_rate: planning cycles per second [Hz].
        behaviour_rate: road-user decisions per second [Hz].
        timestep: physics step [s].
        noise: observation noise.
        max_penetration: geom overlap beyond which the run fails as diverged [m].
        rest_speed: a body below this speed is at rest [m/s].
        settle_time: the run ends this long after every body involved in a collision
            has come to rest (secondary collisions may still follow) [s].
        post_crash_time: longest time after the first collision before ending [s].
        distance_interval: physics steps between minimum-distance checks.
        control_interval: physics steps between controller updates (10: 100 Hz).
        control: tracking controller.
        predictor: name of a registered predictor that replaces the planner
            configuration's ``[prediction] model`` (None keeps it).
        stall: at the time limit, what counts as a standing ego and a blocked way
            (outcomes ``timeout``, ``stopped_safely``, ``no_progress``; ``loop.progress``).
        post_crash: what the ego does after its first contact (``PostCrashPolicy``),
            replacing the scenario's ``ego.post_crash``; None keeps the scenario's.
    """

    replan_rate: float = 10.0
    behaviour_rate: float = 20.0
    timestep: float = 0.001
    noise: ObservationNoise = field(default_factory=ObservationNoise)
    max_penetration: float = 1.5
    rest_speed: float = 0.1
    settle_time: float = 2.0
    post_crash_time: float = 10.0
    distance_interval: int = 10
    control_interval: int = 10
    control: ControlConfig = field(default_factory=ControlConfig)
    predictor: str | None = None
    stall: StallConfig = field(default_factory=StallConfig)
    post_crash: PostCrashPolicy | None = None

    def __post_init__(self) -> None:
        if self.post_crash is not None:
            policy = parse_enum(PostCrashPolicy, self.post_crash, "post-crash policy", "run.post_crash")
            object.__setattr__(self, "post_crash", policy)
        check_positive(
            "run",
            replan_rate=self.replan_rate,
            behaviour_rate=self.behaviour_rate,
            timestep=self.timestep,
            max_penetration=self.max_penetration,
            rest_speed=self.rest_speed,
            settle_time=self.settle_time,
            post_crash_time=self.post_crash_time,
        )
        for name in ("distance_interval", "control_interval"):
            value = getattr(self, name)
            check(
                isinstance(value, int) and not isinstance(value, bool) and value >= 1,
                f"run.{name} must be an integer >= 1, got {value!r}",
            )
        check(
            self.replan_rate * self.timestep <= 1.0,
            "run.replan_rate must not exceed one cycle per physics step",
        )
