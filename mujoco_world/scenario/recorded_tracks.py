"""Recorded trajectories as controller references: vectorised cubic Hermite splines.

``RecordedTracks`` holds the recordings of several bodies in padded arrays and samples
position, velocity, acceleration, heading and yaw rate of all of them at a time, with
one set of numpy operations. Between two recorded states the position follows the
cubic Hermite spline whose tangents are the central-difference velocities of the
recorded positions (Catmull-Rom): position and velocity are continuous, and velocity
and acceleration are the exact derivatives of the position the controller is asked to
follow, so a body that can follow it (within its friction limit) does so to
millimetres. The heading is interpolated linearly in time (unwrapped).

A body exists only while its recording lasts (``present``). Before its first state it
is nowhere, after its last it has left.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from mujoco_world.scenario.imported import RecordedTrajectory

#: Slack on the presence window [s] (half a physics step at 1 ms).
PRESENCE_SLACK_S = 5e-4
#: Largest drive acceleration a recorded body is given to follow its recording [m/s^2]
#: (5 g): noisy recordings ask more than tyres can give (``World`` raises a recorded
#: body's limit from the friction circle to what its recording asks, up to this).
RECORDED_ACCEL_CAP = 5.0 * 9.81


@dataclass(frozen=True, slots=True)
class PeakAcceleration:
    """Where a recording asks most of the body that follows it.

    Attributes:
        value: largest acceleration magnitude of the spline [m/s^2].
        time: when [s].
    """

    value: float
    time: float


class RecordedTracks:
    """Recordings of ``k`` bodies, sampled together.

    Args:
        trajectories: one recording per body.

    Attributes:
        k: number of bodies.
        start, end: (k,) first and last recorded time [s].
    """

    def __init__(self, trajectories: Sequence[RecordedTrajectory]) -> None:
        self.k = len(trajectories)
        counts = np.array([t.states for t in trajectories], dtype=int)
        n = int(counts.max(initial=2))
        self.count = counts
        self.start = np.array([t.start for t in trajectories], dtype=float)
        self.dt = np.array([t.dt for t in trajectories], dtype=float)
        self.end = self.start + (counts - 1) * self.dt
        shape = (self.k, n)
        px, py, yaw = np.zeros(shape), np.zeros(shape), np.zeros(shape)
        for i, t in enumerate(trajectories):
            m = t.states
            # Padding repeats the last state, so every lookup stays inside the row.
            px[i, :m], px[i, m:] = t.x, t.x[-1]
            py[i, :m], py[i, m:] = t.y, t.y[-1]
            unwrapped = np.unwrap(np.asarray(t.yaw, dtype=float))
            yaw[i, :m], yaw[i, m:] = unwrapped, unwrapped[-1]
        self.position = np.stack([px, py], axis=-1)  # (k, n, 2)
        self.yaw = yaw
        self.velocity = self._central_velocities()  # (k, n, 2)
        self._rows = np.arange(self.k)

    def _central_velocities(self) -> np.ndarray:
        """Central differences inside a recording, one-sided at its ends [m/s], (k, n, 2)."""
        p = self.position
        v = np.zeros_like(p)
        dt = self.dt[:, None, None]
        v[:, 1:-1] = (p[:, 2:] - p[:, :-2]) / (2.0 * dt)
        v[:, 0] = (p[:, 1] - p[:, 0]) / self.dt[:, None]
        last = self.count - 1
        rows = np.arange(self.k)
        v[rows, last] = (p[rows, last] - p[rows, last - 1]) / self.dt[:, None]
        v[np.arange(p.shape[1])[None, :] > last[:, None]] = 0.0
        return v

    def present(self, time: float) -> np.ndarray:
        """(k,) bool: which bodies exist at ``time`` [s]."""
        return (time >= self.start - PRESENCE_SLACK_S) & (time <= self.end + PRESENCE_SLACK_S)

    def sample(self, time: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """References of every body at ``time`` [s] (clamped to its recording).

        Returns:
            (p (k, 2) [m], v (k, 2) [m/s], a (k, 2) [m/s^2], yaw (k,) [rad], yaw rate (k,) [rad/s]).
        """
        u = (time - self.start) / self.dt
        last = self.count - 1
        i = np.clip(np.floor(u).astype(int), 0, last - 1)
        f = np.clip(u - i, 0.0, 1.0)
        return self._hermite(i, f, ~self.present(time))

    def _hermite(
        self, i: np.ndarray, f: np.ndarray, outside: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        rows = self._rows
        h = self.dt[:, None]
        p0, p1 = self.position[rows, i], self.position[rows, i + 1]
        m0, m1 = self.velocity[rows, i], self.velocity[rows, i + 1]
        u = f[:, None]
        u2, u3 = u * u, u * u * u
        p = (2 * u3 - 3 * u2 + 1) * p0 + (u3 - 2 * u2 + u) * h * m0
        p = p + (-2 * u3 + 3 * u2) * p1 + (u3 - u2) * h * m1
        v = (6 * u2 - 6 * u) * (p0 - p1) / h + (3 * u2 - 4 * u + 1) * m0 + (3 * u2 - 2 * u) * m1
        a = (12 * u - 6) * (p0 - p1) / (h * h) + ((6 * u - 4) * m0 + (6 * u - 2) * m1) / h
        y0, y1 = self.yaw[rows, i], self.yaw[rows, i + 1]
        yaw = y0 + f * (y1 - y0)
        rate = (y1 - y0) / self.dt
        # Outside its recording a body holds its first or last state, standing.
        v = np.where(outside[:, None], 0.0, v)
        a = np.where(outside[:, None], 0.0, a)
        rate = np.where(outside, 0.0, rate)
        return p, v, a, yaw, rate

    def peak_accelerations(self) -> list[PeakAcceleration]:
        """The largest acceleration each spline asks for (at its knots, where it peaks).

        Within a segment the spline's acceleration is linear in time, so its largest
        magnitude lies at a segment's start or end.
        """
        out = []
        p, v = self.position, self.velocity
        for i in range(self.k):
            m = int(self.count[i])
            h = self.dt[i]
            dp = p[i, 1:m] - p[i, : m - 1]
            m0, m1 = v[i, : m - 1], v[i, 1:m]
            a_start = 6 * dp / h**2 - (4 * m0 + 2 * m1) / h
            a_end = -6 * dp / h**2 + (2 * m0 + 4 * m1) / h
            mags = np.concatenate([np.hypot(*a_start.T), np.hypot(*a_end.T)])
            k = int(np.argmax(mags))
            segment = k % (m - 1) + (1 if k >= m - 1 else 0)
            out.append(PeakAcceleration(float(mags[k]), float(self.start[i] + segment * h)))
        return out


__all__ = ["PRESENCE_SLACK_S", "RECORDED_ACCEL_CAP", "PeakAcceleration", "RecordedTracks"]
