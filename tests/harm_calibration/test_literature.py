"""Literature anchors (tolerances stated per row).

Car occupants, reduced symmetric model, dv = closing / 2 between equal-mass cars,
model within a factor of 2.5 of the reported 10 % MAIS3+ risk:
TARGET (US crash data): 99 km/h frontal, 73 km/h near-side, 126 km/h rear-end;
Jurewicz et al. 2016: head-on at 30 km/h each. Pedestrians (Tefft 2013): AIS4+
10/25/50/75 % at 27.5/40.1/53.1/65.7 km/h, death 10 % at 38.8 and 50 % at 65.3 km/h;
the pedestrian MAIS3+ model must be at or above them.
"""

import pytest

from harm_calibration.literature import ANCHORS, CAR_FACTOR, literature_markdown, literature_table

# (case, speed [km/h], model risk of the reduced symmetric model, to 0.1 percentage point)
CAR_GOLDEN = [
    ("frontal", 99.0, 0.117),
    ("near-side", 73.0, 0.082),
    ("rear-end", 126.0, 0.143),
    ("head-on, 30 km/h each", 60.0, 0.048),
]


def test_all_anchors_pass():
    checks = literature_table()
    assert len(checks) == len(ANCHORS) == 10
    failed = [c for c in checks if not c.passed]
    assert not failed, literature_markdown(failed)


@pytest.mark.parametrize(("case", "speed", "expected"), CAR_GOLDEN)
def test_car_golden_values(case, speed, expected):
    check = next(c for c in literature_table() if c.anchor.case == case)
    assert check.anchor.speed_kmh == speed
    assert check.dv == pytest.approx(speed / 3.6 / 2)
    assert check.predicted == pytest.approx(expected, abs=0.001)
    assert 1 / CAR_FACTOR <= check.predicted / 0.10 <= CAR_FACTOR


def test_pedestrian_model_at_or_above_tefft():
    peds = [c for c in literature_table() if c.anchor.road_user == "pedestrian"]
    assert len(peds) == 6
    for c in peds:
        assert c.predicted >= c.anchor.risk, c


def test_markdown_table_lists_every_anchor():
    text = literature_markdown(literature_table())
    assert text.count("\n") == len(ANCHORS) + 1
    assert "Tefft 2013" in text and "Jurewicz" in text
