"""Exercise 10: estimate the left elbow's viscous damping (N m s/rad) from a bag recorded on a
Mex-One hung on a stand while the excitation routine moved every joint.

Read the bag (`mexone.record.reader.read_bag`, or `mexone identify BAG --params damping --joints
l_elbow --json`, see docs) and fit. This starter returns the URDF's value: the bag's robot is not
the URDF's.
"""

from __future__ import annotations


def estimate(bag: str) -> float:
    return 0.2  # TODO: fit it from the bag
