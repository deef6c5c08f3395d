"""Rigid-mode impact sequences do not create energy (sweep cases with several hits)."""

import numpy as np
import pytest

from harm_calibration.sweep import ImpactCase, launch_case


@pytest.mark.parametrize("case_id", ["bus|20|30|0.5", "car|30|90|0"])
def test_a_second_hit_driven_in_by_a_spin_creates_no_energy(case_id):
    """Multi-impact sequences whose later contact starts gently and is then driven in fast by
    the bodies' spin: the rigid contact once took its damping from the gentle onset, and the
    explicit damping force overshot (the bus case: kinetic energy x 10, ego delta-v 103 m/s
    from 28 m/s; the car case x 2.4)."""
    partner, speed, angle, offset = case_id.split("|")
    m = launch_case(ImpactCase(partner, float(speed), float(angle), float(offset), "e0.1"))
    assert m is not None and m.multi_impact

    def energy(after: bool) -> float:
        total = 0.0
        for body in (m.a, m.b):
            v = np.array(body.velocity_after if after else body.velocity)
            rate = body.yaw_rate_after if after else body.yaw_rate
            inertia = body.mass * (body.length**2 + body.width**2) / 12.0
            total += 0.5 * body.mass * v @ v + 0.5 * inertia * rate**2
        return total

    assert energy(True) < energy(False)
    # Without a rotation-driven energy source, a body's delta-v stays below twice the closing speed.
    assert m.a.dv_impulse < 2.0 * float(speed)
