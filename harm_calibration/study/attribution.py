"""Who drove into whom: each ego-involved collision of a run, classified from its record.

In recorded scenarios the other road users replay their recordings: they cannot react to
the ego, so a follower drives into an ego that brakes harder or earlier than the
recorded vehicle did. Such a crash says little about the planner's choices, and a
reviewer needs it apart from the crashes the ego drives into. ``attribute`` classifies a
collision from what the run record holds of it:

* the bodies' velocities and centres just before the impact and the contact point of the
  first impulse (``ImpactMeasurement``): a body's *approach speed* is its velocity
  component towards the contact point, v . (c - p) / |c - p| [m/s]. The body with the
  larger approach speed is the one that drove into the other (a leader hit from behind
  moves away from its rear contact: its approach speed is negative);
* where the ego was hit: the ``reduced_area`` of the contact point in the ego's frame
  (``rear``: within the rear sector of its footprint);
* how the other body moved: ``BodyRecord.behaviour`` (``recorded``: a replay, blind to the
  ego).

The run's crash is the class of its first ego-involved collision (later contacts of the
same run are its consequences: an ego pushed into the car ahead).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from mujoco_world.evaluation.compare import ImpactRecord
from mujoco_world.physics.impact import BodyImpact

#: Classes of an ego-involved collision, with what each means (report.md and the README).
ATTRIBUTIONS: dict[str, str] = {
    "ego_strikes": "the ego drove into a road user (its approach speed to the contact was the larger)",
    "ego_into_static": "the ego drove into a kerb, wall or fixed obstacle",
    "struck_from_behind_by_replay": ("a replayed recording (blind to the ego) drove into the ego's rear"),
    "struck_by_replay": "a replayed recording drove into the ego's front or side",
    "struck_from_behind": "a road user that is not a replay drove into the ego's rear",
    "struck": "a road user that is not a replay drove into the ego's front or side",
}
#: The class the study shows apart ("crashes excluding struck from behind by a replay").
STRUCK_FROM_BEHIND_BY_REPLAY = "struck_from_behind_by_replay"
#: ``BodyRecord.behaviour`` of a replayed recording.
REPLAY = "recorded"


def approach_speed(body: BodyImpact, contact: tuple[float, float]) -> float:
    """Velocity of ``body`` towards the contact point before the impact [m/s].

    Args:
        body: one body of the impact (world frame).
        contact: contact point (x, y) [m], world frame.

    Returns:
        v . (c - p) / |c - p|; 0 for a static body or a contact at the centre.
    """
    if body.is_static:
        return 0.0
    dx, dy = contact[0] - body.position[0], contact[1] - body.position[1]
    norm = math.hypot(dx, dy)
    if norm == 0.0:
        return 0.0
    return (body.velocity[0] * dx + body.velocity[1] * dy) / norm


def attribute(impact: ImpactRecord, behaviours: Mapping[int, str | None]) -> str:
    """The class (``ATTRIBUTIONS``) of one ego-involved collision.

    Args:
        impact: a collision the ego (entity 0) took part in.
        behaviours: entity index -> ``BodyRecord.behaviour`` of the run's bodies.

    Raises:
        ValueError: the ego is not in the collision.
    """
    if not impact.involves_ego:
        raise ValueError("attribute() classifies ego-involved collisions; the ego (entity 0) is not in it")
    m = impact.measurement
    ego, other = (m.a, m.b) if m.a.entity == 0 else (m.b, m.a)
    if other.is_static:
        return "ego_into_static"
    contact = m.contact_position
    if approach_speed(ego, contact) >= approach_speed(other, contact):
        return "ego_strikes"
    replay = behaviours.get(other.entity) == REPLAY
    if ego.reduced_area == "rear":
        return STRUCK_FROM_BEHIND_BY_REPLAY if replay else "struck_from_behind"
    return "struck_by_replay" if replay else "struck"


__all__ = ["ATTRIBUTIONS", "REPLAY", "STRUCK_FROM_BEHIND_BY_REPLAY", "approach_speed", "attribute"]
