"""What the derived hostile battery found in the baselines (polar_sim.testing.derive), each now
refused with ValueError/TypeError naming the argument, the object unchanged; and the baselines'
part of the module contract (no published preset)."""

import numpy as np
import pytest

from polar_sim.baselines import (DiscreteSDF2D, ICPLocalizer, LikelihoodField, OccupancyGrid2D,
                                 ParticleFilterLocalizer, RoomSDF2D)
from polar_sim.baselines.occupancy import MAX_CELLS
from polar_sim.baselines.particle_filter import MAX_PARTICLES
from polar_sim.testing import state_digest

ANGLES = np.linspace(-np.pi, np.pi, 90, endpoint=False)


def _grid():
    room, g = RoomSDF2D(), OccupancyGrid2D(cell_size=0.1)
    g.update(ANGLES, room.scan((2.0, 1.5, 0.4), ANGLES), (2.0, 1.5, 0.4))
    return g


# A pose far from the origin used to overflow the cell indices ("negative dimensions").
@pytest.mark.parametrize("pose", [(-1e300, 1.5, 0.4), (1e17, 1.5, 0.4)])
def test_grid_refuses_a_scan_it_cannot_index(pose):
    g = _grid()
    before = state_digest(g)
    with pytest.raises(ValueError, match="pose2d"):
        g.update(ANGLES, np.full(90, 2.0), pose)
    assert state_digest(g) == before


# A scan that would grow the grid past MAX_CELLS is refused before anything is allocated.
def test_grid_refuses_growth_past_its_limit():
    g = OccupancyGrid2D(cell_size=1e-6)
    cells = (6.0 / 1e-6) ** 2
    assert cells > MAX_CELLS
    with pytest.raises(ValueError, match="cell_size"):
        g.update(ANGLES, np.full(90, 3.0), (0.0, 0.0, 0.0))
    assert not hasattr(g, "log_odds_")


def test_particle_count_is_bounded():
    with pytest.raises(ValueError, match="n_particles"):
        ParticleFilterLocalizer(n_particles=MAX_PARTICLES + 1, seed=0).initialize(LikelihoodField().fit(_grid()),
                                                                                  (2.0, 1.5, 0.4))


# An odometry jump of 1e300 m used to raise OverflowError in the motion model.
def test_particle_filter_refuses_an_odometry_jump_it_cannot_model():
    pf = ParticleFilterLocalizer(n_particles=50, seed=0).initialize(LikelihoodField().fit(_grid()), (2.0, 1.5, 0.4))
    pf.update(ANGLES, RoomSDF2D().scan((2.0, 1.5, 0.4), ANGLES), (0.0, 0.0, 0.0))
    before = state_digest(pf)
    with pytest.raises(ValueError, match="odom_pose2d"):
        pf.update(ANGLES, RoomSDF2D().scan((2.0, 1.5, 0.4), ANGLES), (-1e300, 0.0, 0.0))
    assert state_digest(pf) == before


# A tiny sigma_hit or a huge max_distance used to raise OverflowError; the far field is z_rand's floor.
@pytest.mark.parametrize("params", [{"sigma_hit": 1e-300}, {"max_distance": 1e300}])
def test_likelihood_field_takes_extreme_widths(params):
    f = LikelihoodField(**params).fit(_grid())
    assert f.log_outside_ == pytest.approx(np.log(f.z_rand / f.max_range))


@pytest.mark.parametrize("occupied, exc", [(np.zeros((8, 8), complex), TypeError),
                                           (np.where(np.eye(8) > 0, np.nan, 0.0), ValueError)])
def test_discrete_sdf_refuses_cells_without_a_truth_value(occupied, exc):
    with pytest.raises(exc, match="occupied"):
        DiscreteSDF2D().fit(occupied, np.zeros(2), 0.1)


# max_correspondence_distance is read only by method="point", but a bad one is refused at fit() either way.
def test_icp_checks_its_gate_at_fit():
    icp = ICPLocalizer(max_correspondence_distance="1.0")
    with pytest.raises(TypeError, match="max_correspondence_distance"):
        icp.fit(_grid())
    assert not hasattr(icp, "map_")


# The specs define no published configuration of any baseline: published() says so.
@pytest.mark.parametrize("cls", [OccupancyGrid2D, DiscreteSDF2D, LikelihoodField, ParticleFilterLocalizer,
                                 ICPLocalizer, RoomSDF2D])
def test_no_published_preset(cls):
    with pytest.raises(ValueError, match="no published preset"):
        cls.published()
