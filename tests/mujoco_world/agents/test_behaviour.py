"""Behaviour models are looked up in a registry, one per behaviour kind."""

import pytest

from mujoco_world.agents.behaviour import BEHAVIOURS
from mujoco_world.scenario.spec import BehaviourKind


def test_every_behaviour_kind_has_a_registered_model():
    assert set(BEHAVIOURS.names()) == {kind.value for kind in BehaviourKind}
    assert not BEHAVIOURS.get("parked").moves and BEHAVIOURS.get("idm").moves
    with pytest.raises(
        ValueError, match="unknown behaviour 'teleport'; allowed: scripted, idm, pedestrian, parked"
    ):
        BEHAVIOURS.get("teleport")
