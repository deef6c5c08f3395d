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

The approach speeds and the test "the ego drove into it" are ``mujoco_world.evaluation.
compare.approach_speed`` and ``ego_strikes`` (the scenario language's ``[expect]
ego_strikes`` checks the same). The run's crash is the class of its first ego-involved
collision (later contacts of the same run are its consequences: an ego pushed into the
car ahead).
"""

from __future__ import annotations

from collections.abc import Mapping

from mujoco_world.evaluation.compare import ImpactRecord, approach_speed, ego_strikes

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
    if ego_strikes(impact):
        return "ego_strikes"
    replay = behaviours.get(other.entity) == REPLAY
    if ego.reduced_area == "rear":
        return STRUCK_FROM_BEHIND_BY_REPLAY if replay else "struck_from_behind"
    return "struck_by_replay" if replay else "struck"


__all__ = ["ATTRIBUTIONS", "REPLAY", "STRUCK_FROM_BEHIND_BY_REPLAY", "approach_speed", "attribute"]
