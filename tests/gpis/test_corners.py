"""Default-mode GPISMap2D at the corners of a box seen against the far walls (0.25 deg beams).

A beam that grazes a corner returns from the far wall, and the observation GP interpolates the
range between the near and the far return. The published re-evaluation replaced samples with an
untrusted normal by whatever its line search found there, without the association gate, which
put corner samples 6-8 cm out in free space (5-18 cm on office2d), and the SDF around them wrong.
"""

import numpy as np
import pytest

from polar_sim.gpis import GPISMap2D

from .scenes import scan_2d, sdf_2d

ANGLES = np.deg2rad(np.arange(-135.0, 135.0, 0.25))
CORNERS = np.array([[5.0, 2.0], [6.0, 2.0]])        # the box's corners facing the drive


def _drive(seed):
    rng = np.random.default_rng(seed)
    m = GPISMap2D()
    for x in np.linspace(1.0, 7.2, 63):               # past the box (5..6, 1..2), 0.6-0.9 m above
        pose = (x, 2.6 + 0.3 * np.sin(x), 0.0)
        m.update(ANGLES, scan_2d(pose, ANGLES, noise=0.01, rng=rng), pose)
    return m


@pytest.fixture(scope="module", params=[0, 1])
def corner_map(request):
    return _drive(request.param)


# every sample on the true surface within 3 sigma of the range noise (old code: 5.7-8.3 cm)
def test_corner_samples_on_surface(corner_map):
    e = np.abs(sdf_2d(corner_map.samples()["points"]))
    assert e.max() <= 0.03


# points 2-10 cm outside the box within 15 cm of the corners the drive saw: the SDF within
# 2.5 cm RMS and on the right side for at least 95 % of them (measured 1.7-2.0 cm and 1-3 %
# wrong; the old code 3.0 cm and 11-12 % wrong, behind the adjacent face's disc or a corner
# sample in free space). The 2 cm bound holds in front of the seen faces (1.2-1.3 cm).
def test_corner_sdf(corner_map):
    rng = np.random.default_rng(5)
    P = np.column_stack([rng.uniform(4.7, 6.3, 200_000), rng.uniform(1.5, 2.3, 200_000)])
    gt = sdf_2d(P)
    dc = np.min(np.linalg.norm(P[:, None] - CORNERS[None], axis=2), 1)
    sel = (gt > 0.02) & (gt < 0.1) & (dc < 0.15)
    assert sel.sum() > 5000
    d, _, _ = corner_map.query(P[sel])
    e = d - gt[sel]
    assert np.sqrt(np.mean(e ** 2)) <= 0.025
    assert np.mean(d < 0) <= 0.05
    front = P[sel, 1] > 2.0
    assert np.sqrt(np.mean(e[front] ** 2)) <= 0.02
