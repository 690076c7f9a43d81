"""Default-mode GPISMap2D sample noise (``_fusion.RangeNoiseModel``) against exact geometry.

The spec's model (position variance 0.01 r^2 plus a view-angle term, normal variance grown by the
same term on re-evaluation) makes samples of far or grazing surfaces fail the drop gate; the
default model derives the noises from the range sigma and the incidence, so they stay."""

import numpy as np

from polar_sim.gpis import GPISMap2D
from polar_sim.gpis._fusion import RangeNoiseModel

ANG = np.deg2rad(np.arange(-135.0, 135.0, 0.25))
SIGMA = 0.01


def _scan(pose, rng):
    """Ranges from pose (x, y, theta) to the floor line y = 0 (x in [0, 30]), with 1 cm noise."""
    x, y, th = pose
    a = ANG + th
    s = np.sin(a)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -y / s
        xh = x + t * np.cos(a)
        ok = (t > 0) & (xh >= 0.0) & (xh <= 30.0) & (t < 29.0)
    return np.where(ok, t + SIGMA * rng.standard_normal(len(a)), np.inf)


def _map(legacy):
    rng = np.random.default_rng(0)
    m = GPISMap2D.published() if legacy else GPISMap2D()
    for x in np.linspace(0.0, 1.0, 11):       # 1 m along the wall, 1 m above it
        pose = (x, 1.0, 0.0)
        m.update(ANG, _scan(pose, rng), pose)
    return m


# the model's variances, exactly as documented (m^2 and rad^2)
def test_model_values():
    m = RangeNoiseModel(0.01, 0.005, 1e-3, kappa=0.5)
    c = np.array([1.0, 0.5, 0.1])
    assert np.allclose(m.position(c), 1e-4 * c ** 2 + 1e-3)
    assert np.allclose(m.normal(np.array([2.0, 2.0, 10.0]), c), (0.5 * 0.01 * c ** 2 / (np.array([2.0, 2.0, 10.0]) * 0.005)) ** 2)
    # |oc| = tanh(15 r (r^-1/2 - rho_hat)) of a range error dr gives back dr (first order)
    r, dr = 9.0, 0.02
    A = np.tanh(15 * r * (r ** -0.5 - (r - dr) ** -0.5))
    assert abs(RangeNoiseModel.residual(abs(A), r, 1.0) - dr) < 1e-3


# a wall seen at grazing incidence from 5-20 m keeps trusted samples on the true line
def test_far_grazing_wall_kept():
    s = _map(False).samples()
    P, sg = s["points"], s["gradient_noise"]
    far = (P[:, 0] > 5.0) & (P[:, 0] < 20.0)
    assert far.sum() >= 10
    assert np.abs(P[far, 1]).max() <= 0.03                        # on the true wall (y = 0)
    assert np.mean(sg[far] <= 0.1001) >= 0.9                       # normals pass the GP gate
    assert np.median(np.abs(s["normals"][far, 1])) >= 0.99           # and are right
    # the published model strips the normals of many of them (27 trusted against 48 here)
    sl = _map(True).samples()
    farl = (sl["points"][:, 0] > 5.0) & (sl["points"][:, 0] < 20.0)
    assert (farl & (sl["gradient_noise"] <= 0.1001)).sum() < 0.75 * (far & (sg <= 0.1001)).sum()


# the SDF on the far stretch: median error <= 5 mm, worst <= 3 cm (measured 0.5-1.5 mm and
# 2.8 cm; the published query's median is 5-6 cm there), and surface() follows the wall
def test_far_grazing_wall_sdf():
    m = _map(False)
    x = np.linspace(6.0, 18.0, 25)
    for off in (0.0, 0.05, -0.05):
        d, _, _ = m.query(np.column_stack([x, np.full_like(x, off)]))
        assert np.median(np.abs(d - off)) <= 0.005, off
        assert np.abs(d - off).max() <= 0.03, off
    L = np.vstack(m.surface())
    seg = (L[:, 0] > 6.0) & (L[:, 0] < 18.0)
    assert seg.sum() > 0 and np.abs(L[seg, 1]).max() <= 0.03
