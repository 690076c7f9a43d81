"""Stage settings of :class:`~polar_sim.gpis.GPISMap2D` and :class:`~polar_sim.gpis.GPISMap3D`.

One frozen dataclass per stage of the pipeline (``docs/specs/gpis.md``). Each stage's base class
documents and checks its fields; its 2D and 3D variants, the ones a map takes, differ only in their
defaults (the spec's quadtree and octree values; the 2D noise stage also has the laser's range
noise and scan model):

- ``observation``: :class:`ObservationConfig2D` / :class:`ObservationConfig3D`, the observation GP
  and occupancy test (spec §3-4);
- ``noise``: :class:`NoiseConfig2D` / :class:`NoiseConfig3D`, sample noise and re-evaluation (§5-6);
- ``tree``: :class:`TreeConfig2D` / :class:`TreeConfig3D`, the quadtree / octree and sample
  spacing (§7);
- ``local_gp``: :class:`LocalGPConfig2D` / :class:`LocalGPConfig3D`, the local GPs and their
  retraining (§8);
- ``distance``: :class:`DistanceConfig2D` / :class:`DistanceConfig3D`, the query and the faithful
  distance (§9).

Each config checks every field in ``__post_init__`` (type, range, finiteness, and the limits of
the sizes, before anything is allocated) and raises ``ValueError``/``TypeError`` naming the
field. The maps store them as their parameters of the same names; ``get_params(deep=True)`` /
``set_params`` reach a field as ``stage__field`` (``m.set_params(local_gp__train_cap=16)``).

The behaviour switches, one table (:data:`SWITCHES`), choose per stage between the default
(with the spec §11 fixes) and the published C++'s behaviour, quirks and bugs included; each
config's ``published()`` sets its switches to the published value, and the maps' ``published()``
is every stage's.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from polar_sim._validation import as_positive_float, check_choice

__all__ = ["SWITCHES", "ObservationConfig", "NoiseConfig", "TreeConfig", "LocalGPConfig", "DistanceConfig",
           "ObservationConfig2D", "ObservationConfig3D", "NoiseConfig2D",
           "NoiseConfig3D", "TreeConfig2D", "TreeConfig3D", "LocalGPConfig2D", "LocalGPConfig3D",
           "DistanceConfig2D", "DistanceConfig3D", "MAX_CLUSTER_NODES", "MAX_TRAIN_CAP",
           "MAX_RANGE_NOISE", "MIN_SAMPLE_SPACING", "REEVALUATIONS"]

#: Every behaviour switch: (the default, the published C++'s behaviour).
SWITCHES = {"spacing_rule": ("strict", "chain"), "retrain": ("changed", "box"),
            "gp_noise": ("model", "published"), "fusion": ("fixed", "published"),
            "query_mode": ("faithful", "published"), "scan_model": ("range", "published")}

#: NoiseConfig2D.reevaluation's choices: the default (the re-evaluation on the scan's returns), then
#: the gates alone (the behaviour before it, kept by the navigation environments' frozen versions).
REEVALUATIONS = ("on_returns", "gated")

#: Tree nodes a cluster cell may hold (2D default 341, 3D 585): a cluster owns a complete
#: subtree down to leaves below min_half.
MAX_CLUSTER_NODES = 100_000
#: train_cap's limit: a local GP of that many samples keeps a Cholesky factor of 8 * cap**2 bytes
#: (134 MB at the limit).
MAX_TRAIN_CAP = 4096
#: range_noise's limit, m: beyond it no beam carries information (and squares of the noise
#: overflow long before 1e300).
MAX_RANGE_NOISE = 100.0
#: sample_spacing's lower limit, m: spacings are divided by.
MIN_SAMPLE_SPACING = 1e-6


def _positive(cfg, names, allow_zero=False):
    for name in names:
        as_positive_float(getattr(cfg, name), name, allow_zero=allow_zero)


def _optional_positive(cfg, name, allow_zero=False):
    v = getattr(cfg, name)
    return None if v is None else as_positive_float(v, name, allow_zero=allow_zero)


def _switches(cfg):
    for name in (f.name for f in dataclasses.fields(cfg)):
        if name in SWITCHES:
            check_choice(getattr(cfg, name), SWITCHES[name], name)


class _Stage:
    """Shared behaviour of the stage configs: ``published()`` and a compact ``replace``."""

    @classmethod
    def published(cls, **overrides):
        """This stage with its switches at the published C++'s behaviour, then ``overrides``."""
        pub = {f.name: SWITCHES[f.name][1] for f in dataclasses.fields(cls) if f.name in SWITCHES}
        return cls(**{**pub, **overrides})

    def replace(self, **changes):
        """A copy with ``changes`` (validated like a new config)."""
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True)
class ObservationConfig(_Stage):
    """Observation GP and occupancy test (spec §3-4).

    The fields of the stage, without defaults: a map takes :class:`ObservationConfig2D` or
    :class:`ObservationConfig3D`.

    Parameters
    ----------
    obs_scale : float
        Observation GP (Ornstein-Uhlenbeck) length scale: rad in 2D, normalised image units (or
        rad, for a lidar) in 3D. Default 0.5.
    obs_noise : float
        Observation GP noise variance. Default 0.01.
    obs_var_thre : float
        Observation-GP variance above which a direction counts as unobservable. Default 0.1 (2D),
        0.04 (3D).
    delx : float
        Finite-difference step and initial line-search step, m. Default 0.01 (2D), 0.001 (3D).
    """

    obs_scale: float
    obs_noise: float
    obs_var_thre: float
    delx: float

    def __post_init__(self):
        _positive(self, ("obs_scale", "obs_noise", "obs_var_thre", "delx"))


@dataclass(frozen=True)
class ObservationConfig2D(ObservationConfig):
    """:class:`ObservationConfig` with the 2D defaults."""

    obs_scale: float = 0.5
    obs_noise: float = 0.01
    obs_var_thre: float = 0.1
    delx: float = 0.01


@dataclass(frozen=True)
class ObservationConfig3D(ObservationConfig):
    """:class:`ObservationConfig` with the 3D defaults."""

    obs_scale: float = 0.5
    obs_noise: float = 0.01
    obs_var_thre: float = 0.04
    delx: float = 0.001


@dataclass(frozen=True)
class NoiseConfig(_Stage):
    """Noise of the surface samples and their re-evaluation (spec §5-6).

    The fields of the stage, without defaults: a map takes :class:`NoiseConfig2D` or
    :class:`NoiseConfig3D`.

    Parameters
    ----------
    min_position_noise : float
        Floor of the samples' position noise (variance, m²). Default 0.01 (2D), 0.001 (3D).
    min_grad_noise : float
        Floor of the samples' gradient noise (variance). Default 0.01.
    map_noise : float
        Noise floor of the map (variance); the prior variance of ``query`` is 1 + map_noise.
        Default 0.01 (2D), 0.005 (3D).
    fusion : {"fixed", "published"}
        Re-evaluation: the fixed line search and slerp normal fusion (weight
        sg_old / (sg_old + sg_new)), or the published ones (3D line search that re-projects the
        original point, inverted weight, unnormalised 3D rotation axis).
    """

    min_position_noise: float
    min_grad_noise: float
    map_noise: float
    fusion: str

    def __post_init__(self):
        _positive(self, ("min_position_noise",))
        _positive(self, ("min_grad_noise", "map_noise"), allow_zero=True)
        _switches(self)


@dataclass(frozen=True)
class NoiseConfig2D(NoiseConfig):
    """:class:`NoiseConfig` with the 2D defaults, and the laser's noise model.

    Parameters
    ----------
    range_noise : float, default=0.01
        Standard deviation of the laser's range noise, m (at most ``MAX_RANGE_NOISE``, 100 m). It
        sets the sample noise (spec §5/§6 replaced by ``_fusion.RangeNoiseModel``): position
        variance ``range_noise² cos²(incidence)`` m² (re-evaluation adds the line-search residual
        and the between-beam term ``(r dθ sin(incidence))²``; fused values are floored at
        1e-5 m², and the local GPs add 1e-3 m² to every value noise) and normal variance
        ``(0.5 range_noise cos²(incidence) / (r dθ))²`` rad² (``dθ`` the beam spacing), so far
        and grazing returns keep their normals. Re-evaluation fuses only line searches that
        reached the observed surface within 3 σ (at least 5 cm) with a normal facing the sensor.
        Not used with ``scan_model="published"`` (the spec's 0.01 r² and view-angle terms).
    scan_model : {"range", "published"}, default="range"
        The range-sigma noise model, the field of view applied to new samples and re-evaluation
        around the laser; or the published ones (the spec's noise model, the field of view for
        re-evaluation only, re-evaluation around the base).
    reevaluation : {"on_returns", "gated"}, default="on_returns"
        With the range model, "on_returns" adds to the gates above: a line search must end
        within 2 σ of the chords between the scan's own returns (``_scan2d.raw_support``) and
        the normal it fuses lie within 45° of that chord's, a sample whose position is trusted
        but whose normal is not is fused instead of replaced, and a sample alone in its cluster
        is re-evaluated too (spec §6.1's [quirk] never does), so corner samples stay on the
        surface. "gated" applies the gates above alone (the default before issue 35); the
        navigation environments' registered versions keep it, so their episodes replay.
    """

    min_position_noise: float = 0.01
    min_grad_noise: float = 0.01
    map_noise: float = 0.01
    fusion: str = "fixed"
    range_noise: float = 0.01
    scan_model: str = "range"
    reevaluation: str = "on_returns"

    def __post_init__(self):
        super().__post_init__()
        check_choice(self.reevaluation, REEVALUATIONS, "reevaluation")
        v = as_positive_float(self.range_noise, "range_noise")
        if v > MAX_RANGE_NOISE:
            raise ValueError(f"range_noise: expected at most {MAX_RANGE_NOISE:g} m (MAX_RANGE_NOISE), "
                             f"got {self.range_noise!r}")


@dataclass(frozen=True)
class NoiseConfig3D(NoiseConfig):
    """:class:`NoiseConfig` with the 3D defaults."""

    min_position_noise: float = 0.001
    min_grad_noise: float = 0.01
    map_noise: float = 0.005
    fusion: str = "fixed"


@dataclass(frozen=True)
class TreeConfig(_Stage):
    """The quadtree / octree and the sample spacing (spec §7).

    The fields of the stage, without defaults: a map takes :class:`TreeConfig2D` or
    :class:`TreeConfig3D`.

    Parameters
    ----------
    init_half, cluster_half, min_half, max_half : float
        Root half-length, cluster-cell half-length, minimum sample spacing and root growth limit,
        m; min_half <= cluster_half <= init_half <= 2 max_half, init_half / cluster_half a power
        of two, and a cluster cell at most ``MAX_CLUSTER_NODES`` tree nodes. Default 12.8, 0.8,
        0.2, 102.4 (2D); 0.4, 0.025, 0.00625, 1.6 (3D: the map spans at most 6.4 m; raise these
        for room scale).
    sample_spacing : float or None
        Minimum distance between samples, enforced across cell borders (the published code
        checks only the cell chain, giving about half the intended spacing), m, at least
        ``MIN_SAMPLE_SPACING``; None: min_half (2D), 0.01 m (3D). In 2D it applies between
        samples of the same face only: a sample whose trusted normal points away from the new
        one's (dot < -0.5) is the other face of a thin wall (the tree then gets leaves of
        half-length min_half / 2 so that both faces fit). Default None.
    spacing_rule : {"strict", "chain"}
        "strict": ``sample_spacing`` enforced across cell borders; "chain": the published
        chain-only test. Default "strict".
    """

    init_half: float
    cluster_half: float
    min_half: float
    max_half: float
    sample_spacing: float | None
    spacing_rule: str

    _DIM = 0

    def __post_init__(self):
        init, cl, mn, mx = (as_positive_float(getattr(self, k), k)
                            for k in ("init_half", "cluster_half", "min_half", "max_half"))
        s = _optional_positive(self, "sample_spacing")
        if s is not None and s < MIN_SAMPLE_SPACING:
            raise ValueError(f"sample_spacing: expected at least {MIN_SAMPLE_SPACING:g} m "
                             f"(MIN_SAMPLE_SPACING), got {self.sample_spacing!r}")
        _switches(self)
        if not mn <= cl <= init <= mx * 2:
            raise ValueError("min_half <= cluster_half <= init_half <= 2*max_half is required")
        # a cluster owns a complete subtree down to leaves below min_half (min_half / 2 for the
        # faces of thin walls): its node count must stay bounded
        lvl, h = 0, cl
        while not h < 0.5 * mn and lvl <= 64:
            h, lvl = h / 2.0, lvl + 1
        B = 1 << self._DIM
        if (B ** (lvl + 1) - 1) // (B - 1) > MAX_CLUSTER_NODES:
            raise ValueError(f"cluster_half/min_half: {cl} / {mn} gives clusters of more than "
                             f"{MAX_CLUSTER_NODES} tree nodes (the limit); raise min_half or lower "
                             "cluster_half")
        r = init / cl
        if abs(np.log2(r) - round(np.log2(r))) > 1e-9:
            raise ValueError("init_half / cluster_half must be a power of two")


@dataclass(frozen=True)
class TreeConfig2D(TreeConfig):
    """:class:`TreeConfig` with the 2D (quadtree) defaults."""

    init_half: float = 12.8
    cluster_half: float = 0.8
    min_half: float = 0.2
    max_half: float = 102.4
    sample_spacing: float | None = None
    spacing_rule: str = "strict"

    _DIM = 2


@dataclass(frozen=True)
class TreeConfig3D(TreeConfig):
    """:class:`TreeConfig` with the 3D (octree) defaults."""

    init_half: float = 0.4
    cluster_half: float = 0.025
    min_half: float = 0.00625
    max_half: float = 1.6
    sample_spacing: float | None = None
    spacing_rule: str = "strict"

    _DIM = 3


@dataclass(frozen=True)
class LocalGPConfig(_Stage):
    """The local GPs of the clusters and their retraining (spec §8).

    The fields of the stage, without defaults: a map takes :class:`LocalGPConfig2D` or
    :class:`LocalGPConfig3D`.

    Parameters
    ----------
    map_scale : float
        Matérn-3/2 length scale of the local GPs, m; the 2D query searches clusters within
        4 map_scale. Default 1.2 (2D), 0.04 (3D).
    fbias : float
        Value target of every surface sample is -fbias; the published SDF is f + fbias.
        Default 0.2.
    retrain_tol : float or None
        A re-evaluated sample triggers retraining of the GPs that use it only once it has moved
        more than this (or its normal turned > 0.05 rad, or a noise changed > 2x) since they were
        trained, m; None: 0.005 (2D), 0.0005 (3D); 0: retrain on every change (as published).
        Default None.
    train_cap : int or None
        Each local GP trains on at most this many samples (1 to ``MAX_TRAIN_CAP``, 4096), the
        nearest its cluster's centre among those within the training radius; None: all of them.
        The published retraining (``retrain="box"``) has no cap. Training costs O(m³) in the m
        samples: the cap bounds the update time and memory in cluttered rooms (the Intel Lab: a
        median of 244, up to 450). Default 32 (2D: chosen on office2d's dev seeds, where it
        leaves every accuracy figure unchanged), None (3D).
    retrain : {"changed", "box"}
        "changed": retrain exactly the clusters whose training set changed by more than
        ``retrain_tol``; "box": the published box around the active clusters, every change, with
        its |U| <= 1 carry-over (spec §8.1). Default "changed".
    gp_noise : {"model", "published"}
        Value noise of the local GPs: the default model (samples without a gradient keep their
        position noise, plus a value floor) or the published one (2.0, no floor, the 2D
        x-gradient noise quirk). Default "model".
    """

    map_scale: float
    fbias: float
    retrain_tol: float | None
    train_cap: int | None
    retrain: str
    gp_noise: str

    def __post_init__(self):
        _positive(self, ("map_scale",))
        _positive(self, ("fbias",), allow_zero=True)
        _optional_positive(self, "retrain_tol", allow_zero=True)
        cap = self.train_cap
        if cap is not None and (isinstance(cap, (bool, np.bool_)) or not isinstance(cap, (int, np.integer))
                                or not 1 <= cap <= MAX_TRAIN_CAP):
            raise ValueError(f"train_cap: expected None or an integer in [1, {MAX_TRAIN_CAP}] "
                             f"(MAX_TRAIN_CAP), got {cap!r}")
        _switches(self)


@dataclass(frozen=True)
class LocalGPConfig2D(LocalGPConfig):
    """:class:`LocalGPConfig` with the 2D defaults."""

    map_scale: float = 1.2
    fbias: float = 0.2
    retrain_tol: float | None = None
    train_cap: int | None = 32
    retrain: str = "changed"
    gp_noise: str = "model"


@dataclass(frozen=True)
class LocalGPConfig3D(LocalGPConfig):
    """:class:`LocalGPConfig` with the 3D defaults."""

    map_scale: float = 0.04
    fbias: float = 0.2
    retrain_tol: float | None = None
    train_cap: int | None = None
    retrain: str = "changed"
    gp_noise: str = "model"


@dataclass(frozen=True)
class DistanceConfig(_Stage):
    """The query (spec §9) and its faithful distance.

    The fields of the stage, without defaults: a map takes :class:`DistanceConfig2D` or
    :class:`DistanceConfig3D`.

    Parameters
    ----------
    blend_near, blend_far : float
        The query is the GPIS within ``blend_near`` of the nearest surfel, the surfel distance
        beyond ``blend_far``, and a smoothstep blend in between, m (blend_near < blend_far).
        Default 0.05, 0.25 (2D: the GP's extrapolation past the end of a face, 0.1-0.4 m beyond
        a corner or into a door, is the larger error there; the surfel distance to the end of
        the face is exact), 0.002, 0.006 (3D).
    surfel_radius : float or None
        Radius of the disc each sample stands for in the far-field distance, m; None:
        min_half / 2 (2D), the sample spacing / √3 (3D: 5.8 mm, so that the discs of a face
        leave no holes). Default None.
    free_res : float or None
        Cell size of the observed-free-space grid (the sign and variance far away), m; None:
        0.05 (2D), cluster_half (3D). The grid sets the sign only beyond one cell diagonal of
        the nearest surfel. Default None.
    query_mode : {"faithful", "published"}
        "faithful": GPIS near surfaces blended into the surfel distance; "published": the
        published SDF ``f + fbias`` of the nearest clusters' GPs only (and ``surface()`` keeps
        the published variance cut). Default "faithful".
    """

    blend_near: float
    blend_far: float
    surfel_radius: float | None
    free_res: float | None
    query_mode: str

    def __post_init__(self):
        near = as_positive_float(self.blend_near, "blend_near", allow_zero=True)
        far = as_positive_float(self.blend_far, "blend_far")
        _optional_positive(self, "surfel_radius")
        _optional_positive(self, "free_res")
        _switches(self)
        if not near < far:
            raise ValueError("blend_near/blend_far: expected blend_near < blend_far")


@dataclass(frozen=True)
class DistanceConfig2D(DistanceConfig):
    """:class:`DistanceConfig` with the 2D defaults."""

    blend_near: float = 0.05
    blend_far: float = 0.25
    surfel_radius: float | None = None
    free_res: float | None = None
    query_mode: str = "faithful"


@dataclass(frozen=True)
class DistanceConfig3D(DistanceConfig):
    """:class:`DistanceConfig` with the 3D defaults."""

    blend_near: float = 0.002
    blend_far: float = 0.006
    surfel_radius: float | None = None
    free_res: float | None = None
    query_mode: str = "faithful"
