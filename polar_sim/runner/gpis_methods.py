"""The built-in plug-ins of the GPIS experiments: 2D/3D mappers and 2D localisers.

Each class follows its kind's protocol (:mod:`polar_sim.runner.methods`); ``methods.py``
registers them by name. Heavy modules are imported on first use, so importing this module (and
the registry) stays cheap.

Mappers (``mapper2d``): :class:`GridMapper2D` (an occupancy grid whose distance field is its
signed EDT and whose surface is its occupied cells next to free ones) and :class:`EDTMapper2D`
(the same grid; its surface is the zero contour of the interpolated EDT). The GPIS maps
(``GPISMap2D``, ``GPISMap3D``) follow the protocols themselves.

Localisers (``localizer2d``): :class:`ICPGLocalizer2D` (ICP-G on a GPIS map),
:class:`ICPDLocalizer2D` (ICP-D on the signed EDT of a 5 cm grid, or on the exact SDF sampled on a
5 cm grid: the dissertation's ground-truth discrete SDF), :class:`PFLocalizer2D` (MCL on the grid's
likelihood field). ICP localisers start each registration from the previous estimate moved by the
odometry increment and keep that prediction when a registration does not return status "ok"
(counted in ``not_ok_``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["scan_to_map_odometry", "call_factory", "pf_factory", "icpd_gt", "GridMapper2D", "EDTMapper2D", "ICPGLocalizer2D", "ICPDLocalizer2D", "PFLocalizer2D",
           "gpis2d", "gpis2d_legacy", "gpis3d", "gpis3d_legacy"]


def call_factory(factory, **available):
    """Call ``factory`` with those of the ``available`` keywords its signature names (a ``**kwargs``
    catch-all gets none of them); see the optional keywords in :mod:`polar_sim.runner.methods`."""
    import inspect

    try:
        params = inspect.signature(factory).parameters.values()
    except (TypeError, ValueError):  # callables without a signature get nothing
        return factory()
    names = {p.name for p in params if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD)}
    return factory(**{k: v for k, v in available.items() if k in names})


def pf_factory(n_particles):
    """A factory of :class:`PFLocalizer2D` with ``n_particles`` (it accepts ``seed`` and ``init_std``)."""
    def factory(*, seed=0, init_std=(0.1, 0.1, 0.05)):
        return PFLocalizer2D(n_particles, seed=seed, init_std=init_std)

    factory.__name__ = f"pf{n_particles}"
    return factory


def icpd_gt(*, exact_sdf):
    """ICP-D on the ground-truth discrete SDF (:class:`ICPDLocalizer2D` with ``truth=True``)."""
    return ICPDLocalizer2D(truth=True, exact_sdf=exact_sdf)


def gpis2d(**params):
    """``GPISMap2D`` taking the sensor pose (``sensor_offset=(0, 0)``), every other parameter at its
    default; ``params`` are parameters or stage fields (``local_gp__train_cap=16``)."""
    from polar_sim.gpis import GPISMap2D

    return GPISMap2D(sensor_offset=(0.0, 0.0)).set_params(**params)


def gpis2d_legacy(**params):
    """``GPISMap2D.published()``: the published behaviour, taking the sensor pose."""
    from polar_sim.gpis import GPISMap2D

    return GPISMap2D.published(**{"sensor_offset": (0.0, 0.0), **params})


def gpis3d(**params):
    """``GPISMap3D()`` with its defaults; ``params`` are parameters or stage fields."""
    from polar_sim.gpis import GPISMap3D

    return GPISMap3D().set_params(**params)


def gpis3d_legacy(**params):
    """``GPISMap3D.published()``: the published behaviour."""
    from polar_sim.gpis import GPISMap3D

    return GPISMap3D.published(**params)


class _GridBase:
    """An occupancy grid whose ``query`` is its signed EDT (``DiscreteSDF2D``, rebuilt after updates)."""

    def __init__(self, cell_size=0.05):
        from polar_sim.baselines import OccupancyGrid2D

        self.cell_size = cell_size
        self.grid = OccupancyGrid2D(cell_size=cell_size)
        self._edt = None

    def update(self, angles, ranges, pose2d):
        self.grid.update(angles, ranges, pose2d)
        self._edt = None
        return self

    def edt(self):
        """The signed EDT (``DiscreteSDF2D``) of the current grid."""
        from polar_sim.baselines import DiscreteSDF2D

        if self._edt is None:
            self._edt = DiscreteSDF2D.from_grid(self.grid)
        return self._edt

    def query(self, points):
        return self.edt().query(points)


class GridMapper2D(_GridBase):
    """Occupancy grid as a ``mapper2d``: ``query`` is the signed EDT of the grid, ``surface_points()``
    the centres of the occupied cells that touch a free cell."""

    def surface_points(self):
        return self.grid.surface_points()


class EDTMapper2D(_GridBase):
    """The signed EDT of an occupancy grid as a ``mapper2d``: its surface is the zero contour of the
    field (marching squares on the cell-centre distances), as polylines."""

    def surface(self):
        from skimage.measure import find_contours

        e = self.edt()
        return [e.origin_ + (ln + 0.5) * e.cell_size_ for ln in find_contours(e.sdf_, 0.0) if len(ln) >= 2]


def _grid(angles, ranges, poses, cell):
    from polar_sim.baselines import OccupancyGrid2D

    g = OccupancyGrid2D(cell_size=cell)
    for p, r in zip(poses, ranges):
        g.update(angles, r, p)
    return g


class _ICPBase:
    """Tracks by registration from the previous estimate moved by the odometry increment."""

    def reset(self, pose2d):
        self.pose_ = np.asarray(pose2d, float).copy()
        self.not_ok_ = 0
        return self

    def step(self, angles, ranges, odometry_delta):
        from polar_sim.geometry import compose2d

        pred = compose2d(self.pose_, np.asarray(odometry_delta, float))
        pose, _, info = self._register((angles, ranges), pred)
        if info["status"] != "ok":
            self.not_ok_ += 1
            pose = pred
        self.pose_ = np.asarray(pose, float)
        return self.pose_.copy()


class ICPGLocalizer2D(_ICPBase):
    """ICP-G (``polar_sim.gpis.localize``) on a GPIS map fused from the mapping drive at its poses.
    ``map_factory``: the mapper (default :func:`gpis2d`); ``**localize_kw`` go to ``localize``."""

    def __init__(self, map_factory=None, **localize_kw):
        self.map_factory = map_factory
        self.localize_kw = localize_kw

    def fit(self, angles, ranges, poses):
        self.map_ = (self.map_factory or gpis2d)()
        for p, r in zip(poses, ranges):
            self.map_.update(angles, r, p)
        return self

    def _register(self, scan, pred):
        from polar_sim.gpis.localize import localize

        return localize(self.map_, scan, pred, **self.localize_kw)


class ICPDLocalizer2D(_ICPBase):
    """ICP-D (``ICPLocalizer(method="sdf")``): Gauss-Newton on a discrete SDF.

    ``truth=False``: the signed EDT of a ``cell`` occupancy grid of the mapping drive.
    ``truth=True``: the dissertation's ground-truth discrete SDF: the scene's exact SDF
    (``exact_sdf``, a callable the experiment passes) sampled at ``cell`` over the mapped area plus
    1 m, interpolated like the EDT (``DiscreteSDF2D.from_values``).
    """

    def __init__(self, *, truth=False, cell=0.05, exact_sdf=None):
        self.truth = truth
        self.cell = cell
        self.exact_sdf = exact_sdf

    def fit(self, angles, ranges, poses):
        from polar_sim.baselines import DiscreteSDF2D, ICPLocalizer
        from polar_sim.metrics.maps import hit_points

        if not self.truth:
            self.icp_ = ICPLocalizer(method="sdf").fit(_grid(angles, ranges, poses, self.cell))
            self.map_ = self.icp_.map_
            return self
        if self.exact_sdf is None:
            raise ValueError("exact_sdf: the ground-truth ICP-D needs the scene's exact SDF (a callable)")
        h = np.vstack([hit_points(angles, poses, ranges), np.asarray(poses)[:, :2]])
        lo = np.floor((h.min(0) - 1.0) / self.cell) * self.cell
        hi = h.max(0) + 1.0
        xs = lo[0] + (np.arange(int(np.ceil((hi[0] - lo[0]) / self.cell))) + 0.5) * self.cell
        ys = lo[1] + (np.arange(int(np.ceil((hi[1] - lo[1]) / self.cell))) + 0.5) * self.cell
        X, Y = np.meshgrid(xs, ys, indexing="ij")
        vals = np.asarray(self.exact_sdf(np.column_stack([X.ravel(), Y.ravel()]))).reshape(X.shape)
        self.map_ = DiscreteSDF2D.from_values(vals, lo, self.cell)
        self.icp_ = ICPLocalizer(method="sdf").fit(self.map_)
        return self

    def _register(self, scan, pred):
        return self.icp_.localize(scan, pred)


class PFLocalizer2D:
    """MCL (``ParticleFilterLocalizer``) on the likelihood field of a 5 cm grid of the mapping drive.

    ``reset`` draws ``n_particles`` around the pose with standard deviations ``init_std`` (m, m,
    rad); each ``step`` integrates the odometry increment into an odometry pose and updates the
    filter with it and the scan; the estimate is the weighted mean.
    """

    def __init__(self, n_particles=1000, *, seed=0, init_std=(0.1, 0.1, 0.05), cell=0.05):
        self.n_particles = n_particles
        self.seed = seed
        self.init_std = init_std
        self.cell = cell

    def fit(self, angles, ranges, poses):
        from polar_sim.baselines import LikelihoodField

        self.field_ = LikelihoodField().fit(_grid(angles, ranges, poses, self.cell))
        return self

    def reset(self, pose2d):
        from polar_sim.baselines import ParticleFilterLocalizer

        self.pf_ = ParticleFilterLocalizer(n_particles=int(self.n_particles), seed=int(self.seed))
        self.pf_.initialize(self.field_, pose2d, std=tuple(self.init_std))
        self.odom_ = np.asarray(pose2d, float).copy()
        self._first = True
        return self

    def step(self, angles, ranges, odometry_delta):
        from polar_sim.geometry import compose2d

        delta = np.asarray(odometry_delta, float)
        if self._first and np.any(delta != 0):
            self.pf_.predict(self.odom_)   # record the reset pose, so the first increment moves the particles
        self.odom_ = compose2d(self.odom_, delta)
        self._first = False
        self.pf_.update(angles, ranges, self.odom_)
        return self.pf_.pose_.copy()


def scan_to_map_odometry(map_factory, angles, ranges, odom, start):
    """Poses (n, 3) of a scan-to-map odometry: scan k is registered by ICP-G to the map of scans
    0..k-1 fused at their estimated poses, starting from the previous estimate moved by the odometry
    increment (``odom`` (n, 3): odometry poses), then fused at its estimate. A registration that does
    not return status "ok" keeps the prediction. No loop closure: the estimate drifts."""
    from polar_sim.geometry import between2d, compose2d
    from polar_sim.gpis.localize import localize

    m, est = map_factory(), [np.asarray(start, float).copy()]
    m.update(angles, ranges[0], est[0])
    for k in range(1, len(ranges)):
        pred = compose2d(est[-1], between2d(odom[k - 1], odom[k]))
        pose, _, info = localize(m, (angles, ranges[k]), pred)
        est.append(np.asarray(pose if info["status"] == "ok" else pred, float))
        m.update(angles, ranges[k], est[-1])
    return np.asarray(est)
