"""Crash pulses of the contact modes: force and crush against time for reference impacts.

``crash_pulses`` runs a few reference impacts in the ``crush`` and ``rigid`` modes with
the impact recorder's force history; ``pulse_table`` and ``write_pulse_figure`` show them:
the car into a rigid wall at 56 km/h (the frontal crash test: 0.5-0.7 m of crush, a pulse
of 70-100 ms, the force highest mid-pulse at 35-50 g), two cars head-on at 56 km/h each,
a car into a pedestrian and into a car's side at 40 km/h.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ethical_planner.road_users import EGO_MASS_KG, EGO_SHAPE, KinematicState
from mujoco_world.physics.impact import ImpactRecorder, ImpactRig
from mujoco_world.physics.scene import BodyProxy, Scene
from mujoco_world.scenario.road import StaticBox
from mujoco_world.scenario.spec import Boundary, ContactMode, ContactSpec

KMH = 1.0 / 3.6
GRAVITY = 9.81


@dataclass(frozen=True, slots=True)
class Pulse:
    """One measured crash pulse.

    Attributes:
        name: the impact. mode: contact mode.
        time: (k,) time after the first contact [s].
        force: (k,) magnitude of the contact force [N].
        crush: (k,) penetration of the two footprints [m].
        mass: the lighter body's mass [kg] (its acceleration is force / mass).
        dv: the ego's delta-v [m/s]. restitution: at the contact point along the normal.
        peak_time: when the force peaked, as a share of the pulse.
    """

    name: str
    mode: str
    time: np.ndarray
    force: np.ndarray
    crush: np.ndarray
    mass: float
    dv: float
    restitution: float
    peak_time: float

    @property
    def duration(self) -> float:
        """Pulse length [s]."""
        return float(self.time[-1])

    @property
    def max_crush(self) -> float:
        """Deepest penetration [m]."""
        return float(self.crush.max())

    @property
    def peak_g(self) -> float:
        """Peak acceleration of the lighter body [g]."""
        return float(self.force.max() / (self.mass * GRAVITY))

    def summary(self) -> dict[str, float | str]:
        """The table row as a mapping (``etp impacts --pulses --json``)."""
        return {
            "name": self.name,
            "mode": self.mode,
            "duration_s": self.duration,
            "max_crush_m": self.max_crush,
            "peak_g": self.peak_g,
            "peak_time_share": self.peak_time,
            "dv_mps": self.dv,
            "restitution": self.restitution,
        }


def _ego() -> BodyProxy:
    return BodyProxy("ego", "car", EGO_SHAPE.length, EGO_SHAPE.width, EGO_MASS_KG)


def _wall_pulse(mode: ContactMode, speed: float) -> Pulse:
    wall = StaticBox((5.0, 0.0), 1.0, 5.0, 0.5, 0.0, Boundary.WALL)
    scene = Scene([_ego()], [wall], ContactSpec(mode=mode))
    recorder = ImpactRecorder(scene, trace=True)
    x0 = 4.0 - 0.5 * EGO_SHAPE.length - 0.05
    scene.set_states(np.array([x0]), np.zeros(1), np.zeros(1), np.array([speed]), np.zeros(1))
    for _ in range(5000):
        done = scene.step(recorder)
        if done:
            return _pulse(f"car into a wall, {speed / KMH:.0f} km/h", mode, done[0], recorder.traces)
    raise RuntimeError("the car never reached the wall")


def _pair_pulse(name: str, mode: ContactMode, partner: str, state_a: KinematicState, state_b: KinematicState):
    rig = ImpactRig(
        _ego(), BodyProxy.of_type("partner", partner), ContactSpec(mode=mode), trace=True, brake=False
    )
    m = rig.launch(state_a, state_b)
    return _pulse(name, mode, m, {(0, 1, m.time): rig.last_trace})


def _pulse(name: str, mode: ContactMode, m, traces) -> Pulse:  # noqa: ANN001
    trace = traces[(m.a.entity, m.b.entity, m.time)]
    first = m.impulse_times[0][1]
    rows = trace[trace[:, 0] - m.time <= first]
    return Pulse(
        name=name,
        mode=mode.value,
        time=rows[:, 0] - m.time,
        force=np.hypot(rows[:, 1], rows[:, 2]),
        crush=rows[:, 3],
        mass=min(m.a.mass, m.b.mass),
        dv=m.a.dv_first,
        restitution=m.restitution,
        peak_time=m.peak_time / max(first, 1e-9),
    )


def crash_pulses() -> list[Pulse]:
    """The reference impacts in the crush mode, and the wall impact in the rigid mode."""
    half = 0.5 * EGO_SHAPE.length
    out = [_wall_pulse(ContactMode.CRUSH, 56 * KMH), _wall_pulse(ContactMode.RIGID, 56 * KMH)]
    out.append(
        _pair_pulse(
            "two cars head-on, 56 km/h each", ContactMode.CRUSH, "car",
            KinematicState(0, 0, 0, 56 * KMH), KinematicState(half + 2.25 + 0.05, 0, math.pi, 56 * KMH),
        )
    )  # fmt: skip
    out.append(
        _pair_pulse(
            "car into a car's side, 40 km/h", ContactMode.CRUSH, "car",
            KinematicState(0, 0, 0, 40 * KMH), KinematicState(half + 0.9 + 0.05, 0, 0.5 * math.pi, 0),
        )
    )  # fmt: skip
    out.append(
        _pair_pulse(
            "car into a pedestrian, 40 km/h", ContactMode.CRUSH, "pedestrian",
            KinematicState(0, 0, 0, 40 * KMH), KinematicState(half + 0.25 + 0.05, 0.3, 0.5 * math.pi, 0),
        )
    )  # fmt: skip
    return out


def pulse_table(pulses: list[Pulse]) -> str:
    """Markdown table of the pulses."""
    lines = [
        "| impact | mode | pulse [ms] | max crush [m] | peak, lighter body [g] | peak at [share of pulse] "
        "| ego dv [m/s] | e |",
        "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for p in pulses:
        lines.append(
            f"| {p.name} | {p.mode} | {1e3 * p.duration:.1f} | {p.max_crush:.3f} | {p.peak_g:.1f} | "
            f"{p.peak_time:.2f} | {p.dv:.2f} | {p.restitution:.3f} |"
        )
    return "\n".join(lines)


def write_pulse_figure(out_dir: Path, pulses: list[Pulse]) -> str:
    """Force (in g of the ego) and crush against time, crush pulses beside the rigid one."""
    from harm_calibration.figures import _pyplot, _save

    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(7.2, 3.0))
    colours = ("#0072B2", "#7f7f7f", "#D55E00", "#009E73", "#CC79A7")
    styles = ("-", "--", ":", "-", "-")
    for p, colour, style in zip(pulses, colours, styles, strict=False):
        label = f"{p.name} ({p.mode})"
        width = 2.0 if style == ":" else 1.2
        axes[0].plot(1e3 * p.time, p.force / (p.mass * GRAVITY), style, color=colour, lw=width, label=label)
        axes[1].plot(1e3 * p.time, p.crush, style, color=colour, lw=width)
    axes[0].set(xlabel="time after first contact [ms]", ylabel="acceleration of the lighter body [g]",
                xlim=(0, 110), ylim=(0, 60), title="Contact force / mass")  # fmt: skip
    axes[1].set(xlabel="time after first contact [ms]", ylabel="crush (penetration) [m]", xlim=(0, 110),
                title="Crush")  # fmt: skip
    for ax in axes:
        ax.grid(True, lw=0.3, alpha=0.5)
    fig.legend(*axes[0].get_legend_handles_labels(), loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=2,
               frameon=False)  # fmt: skip
    rigid = [p for p in pulses if p.mode == "rigid"]
    note = f"; rigid mode dashed: {1e3 * rigid[0].duration:.1f} ms, {rigid[0].peak_g:.0f} g" if rigid else ""
    fig.suptitle(f"Crash pulses of the crush mode{note}", y=1.02)
    return _save(fig, out_dir, "crash_pulses")


__all__ = ["Pulse", "crash_pulses", "pulse_table", "write_pulse_figure"]
