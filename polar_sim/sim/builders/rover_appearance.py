"""Randomised appearance of the rover scenes: ground families, sky and horizon, lighting.

``World("rover_flat", appearance=...)`` (and ``rover_terrain``) takes

- ``None`` (default): the scene as it always was (asphalt, gravel, grass and dirt zones, a blue
  gradient sky, the fixed sun);
- ``"random"``: every ground zone of a random family, a random sky and light, drawn from the world
  seed;
- a family name (one of :data:`FAMILIES`): every zone of that family, with its own seeded colours,
  and a random sky and light;
- an explicit spec, a dict (see :func:`resolve_appearance`), e.g.
  ``{"ground": {"family": "checker", "colour": [90, 90, 95], "colour2": [200, 200, 190]},
  "sky": {"kind": "plain", "colour": [0, 0, 0]}, "light": {"intensity": 0.8}}``.

The geometry (terrain, route, obstacles) never depends on the appearance: one seed gives the same
world under every appearance, so a route's truth is the same. The resolved spec (every field
filled in, including the seed of the texture noise) is in ``World.meta.appearance``; passing it
back builds the same pixels. Everything is generated procedurally; no image asset ships.
"""

from __future__ import annotations

import colorsys
import copy
import numbers

import numpy as np

__all__ = ["FAMILIES", "RANDOM_FAMILIES", "SKIES", "LIGHT_FIELDS", "resolve_appearance", "sample_appearance", "describe_families"]

#: Ground families: description, the texture repeat (m) and the options each accepts with defaults.
#: ``colour``/``colour2`` are RGB 0..255; ``contrast`` scales the fine detail (0 = none).
FAMILIES = {
    "speckle": ("fine grey-level speckle with sparse bright specks (colour2), like fine asphalt", 4.0,
                {"colour": [110, 110, 112], "colour2": [220, 220, 220], "contrast": 0.25, "density": 0.03}),
    "gravel": ("coarse gravel: stones of 4-10 texels (3-8 cm) between colour and colour2", 4.0,
               {"colour": [120, 110, 98], "colour2": [150, 140, 125], "contrast": 0.4, "stone_px": [4, 10]}),
    "grass": ("grass-like blades, green (colour) with dry patches (colour2)", 4.0,
              {"colour": [60, 118, 40], "colour2": [150, 140, 70], "contrast": 0.3}),
    "uniform": ("flat uniform colour with a faint grain (contrast 0.03: about +-3 grey levels)", 4.0,
                {"colour": [128, 124, 118], "colour2": [128, 124, 118], "contrast": 0.03}),
    "stripes": ("painted stripes (colour2) every 3 m across a dark base (colour)", 6.0,
                {"colour": [70, 70, 72], "colour2": [230, 228, 215], "contrast": 0.15, "stripes": 2, "width": 0.05}),
    "checker": ("square tiles (0.5 m) of two colours with dark grout lines", 4.0,
                {"colour": [95, 95, 100], "colour2": [170, 165, 155], "contrast": 0.1, "tiles": 8, "grout": 0.04}),
    "blotches": ("large low-frequency blotches (metres across) of two colours, fine grain on top", 24.0,
                 {"colour": [120, 100, 70], "colour2": [85, 95, 60], "contrast": 0.15, "blotch": 0.08}),
    "pavers": ("running-bond paving slabs (1 x 0.5 m), each of either colour at random, dark joints", 4.0,
               {"colour": [95, 90, 85], "colour2": [165, 150, 135], "contrast": 0.1, "courses": 8, "ratio": 2,
                "joint": 0.06}),
}

#: The families a ``"random"`` appearance draws from. ``pavers`` came later, as the dev split's
#: periodic ground, and is left out so that the random looks drawn before it stay as they were.
RANDOM_FAMILIES = ("speckle", "gravel", "grass", "uniform", "stripes", "checker", "blotches")

#: Sky and horizon kinds with the fields each accepts and their defaults (RGB 0..255; degrees).
SKIES = {
    "plain": {"colour": [140, 184, 235]},
    "gradient": {"colour": [140, 184, 235], "colour2": [230, 240, 255]},
    "clutter": {"colour": [140, 184, 235], "colour2": [230, 240, 255], "clutter_colour": [55, 70, 50],
                "clutter_deg": 4.0},
}

#: Light fields and their defaults: sun intensity (x the default sun), sun azimuth/elevation (deg,
#: where the sun stands), sun colour (RGB factors 0..1), ambient light (0..1).
LIGHT_FIELDS = {"intensity": 1.0, "azimuth_deg": 33.7, "elevation_deg": 70.2, "colour": [1.0, 1.0, 0.954],
                "ambient": 0.35}

N_ZONES = 4  # zones along the route when a family or "random" is asked for (as the default scene)


def describe_families():
    """Rows (family, description, texture repeat m, options with defaults) for documentation."""
    return [(k, d, rep, dict(opts)) for k, (d, rep, opts) in FAMILIES.items()]


def _hsv(rng, h, s, v):
    r, g, b = colorsys.hsv_to_rgb(rng.uniform(*h) % 1.0, rng.uniform(*s), rng.uniform(*v))
    return [int(round(255 * r)), int(round(255 * g)), int(round(255 * b))]


def _sample_zone(rng, family):
    """Seeded colours and options of one zone of ``family`` (muted colours: HSV saturation <= 0.5,
    so the ground stays unlike the saturated obstacles)."""
    z = dict(FAMILIES[family][2])
    if family == "speckle":
        grey = _hsv(rng, (0.0, 1.0), (0.0, 0.15), (0.25, 0.6))
        z.update(colour=grey, colour2=_hsv(rng, (0.0, 1.0), (0.0, 0.1), (0.75, 0.95)),
                 contrast=float(rng.uniform(0.15, 0.35)))
    elif family == "gravel":
        z.update(colour=_hsv(rng, (0.05, 0.12), (0.1, 0.3), (0.35, 0.6)),
                 colour2=_hsv(rng, (0.0, 0.15), (0.0, 0.25), (0.45, 0.75)), contrast=float(rng.uniform(0.3, 0.5)))
    elif family == "grass":
        z.update(colour=_hsv(rng, (0.22, 0.33), (0.45, 0.7), (0.3, 0.55)),
                 colour2=_hsv(rng, (0.12, 0.18), (0.35, 0.55), (0.45, 0.65)), contrast=float(rng.uniform(0.2, 0.4)))
    elif family == "uniform":
        c = _hsv(rng, (0.0, 1.0), (0.0, 0.35), (0.3, 0.7))
        z.update(colour=c, colour2=c)
    elif family == "stripes":
        z.update(colour=_hsv(rng, (0.0, 1.0), (0.0, 0.1), (0.2, 0.35)),
                 colour2=[230, 228, 215] if rng.random() < 0.5 else [235, 200, 60],
                 stripes=int(rng.integers(1, 4)))
    elif family == "checker":
        a = _hsv(rng, (0.0, 1.0), (0.0, 0.3), (0.25, 0.45))
        z.update(colour=a, colour2=_hsv(rng, (0.0, 1.0), (0.0, 0.3), (0.55, 0.8)), tiles=int(rng.choice([4, 8, 16])))
    elif family == "blotches":
        z.update(colour=_hsv(rng, (0.05, 0.35), (0.2, 0.5), (0.3, 0.55)),
                 colour2=_hsv(rng, (0.05, 0.35), (0.2, 0.5), (0.3, 0.55)))
    elif family == "pavers":
        hue = rng.uniform(0.0, 1.0)
        z.update(colour=_hsv(rng, (hue, hue + 0.05), (0.0, 0.3), (0.25, 0.45)),
                 colour2=_hsv(rng, (hue, hue + 0.05), (0.0, 0.3), (0.55, 0.8)), courses=int(rng.choice([4, 8])))
    z["family"] = family
    z["scale_m"] = FAMILIES[family][1]
    return z


def _sample_sky(rng):
    kind = str(rng.choice(list(SKIES)))
    s = {"kind": kind}
    if kind == "plain":
        s["colour"] = _hsv(rng, (0.0, 1.0), (0.0, 0.4), (0.0, 1.0))  # black to white, any tint
    else:
        s["colour"] = _hsv(rng, (0.55, 0.65), (0.1, 0.5), (0.5, 0.95))
        s["colour2"] = _hsv(rng, (0.0, 1.0), (0.0, 0.25), (0.7, 1.0))
    if kind == "clutter":
        s["clutter_colour"] = _hsv(rng, (0.0, 0.4), (0.1, 0.45), (0.12, 0.45))
        s["clutter_deg"] = float(rng.uniform(2.0, 8.0))
    return s


def _sample_light(rng):
    warm = rng.uniform(-1.0, 1.0)  # < 0 cool (blue-ish), > 0 warm (orange-ish)
    col = np.clip(np.array([1.0, 0.96, 0.9]) + warm * np.array([0.0, -0.06, -0.2]) - min(warm, 0) * np.array([0.15, 0.06, 0.0]),
                  0.0, 1.0)
    return {"intensity": float(rng.uniform(0.5, 1.3)), "azimuth_deg": float(rng.uniform(0.0, 360.0)),
            "elevation_deg": float(rng.uniform(15.0, 85.0)), "colour": [float(c) for c in col],
            "ambient": float(rng.uniform(0.2, 0.5))}


def sample_appearance(seed, family=None):
    """A random explicit spec from an int seed: ``N_ZONES`` zones of ``family`` (or each of a random
    family when None), a random sky kind and light. Deterministic in ``seed``; the sky, light and
    texture seed do not depend on ``family``."""
    # One stream per part: under one seed, every family gets the same sky, light and texture seed.
    rz, rs, rl, rt = (np.random.default_rng(np.random.SeedSequence([int(seed), 7002, k])) for k in range(4))
    fams = list(RANDOM_FAMILIES)
    zones = [_sample_zone(rz, family if family is not None else str(rz.choice(fams))) for _ in range(N_ZONES)]
    return {"ground": zones, "sky": _sample_sky(rs), "light": _sample_light(rl),
            "texture_seed": int(rt.integers(0, 2**31 - 1))}


# ---------------------------------------------------------------------------------------------
# validation


def _colour(v, where, hi=255.0):
    a = np.asarray(v, dtype=object)
    if a.shape != (3,) or not all(isinstance(x, numbers.Real) and not isinstance(x, bool) for x in a.tolist()):
        raise ValueError(f"{where}: expected 3 numbers (RGB 0..{hi:g}), got {v!r}")
    c = np.asarray(v, dtype=np.float64)
    if not np.isfinite(c).all() or c.min() < 0 or c.max() > hi:
        raise ValueError(f"{where}: expected RGB values in 0..{hi:g}, got {v!r}")
    return [float(x) for x in c]


def _number(v, where, lo, hi, integer=False):
    ok = isinstance(v, numbers.Integral) if integer else isinstance(v, numbers.Real)
    if isinstance(v, bool) or not ok or not np.isfinite(float(v)) or not lo <= float(v) <= hi:
        kind = "an integer" if integer else "a number"
        raise ValueError(f"{where}: expected {kind} in [{lo:g}, {hi:g}], got {v!r}")
    return int(v) if integer else float(v)


def _check_fields(d, valid, where):
    if not isinstance(d, dict):
        raise ValueError(f"{where}: expected a dict, got {type(d).__name__}")
    unknown = sorted(set(d) - set(valid))
    if unknown:
        raise ValueError(f"{where}: unknown field(s) {unknown}; valid: {sorted(valid)}")


_LIMITS = {"contrast": (0.0, 2.0, False), "density": (0.0, 1.0, False), "stripes": (1, 32, True),
           "width": (0.005, 0.5, False), "tiles": (1, 64, True), "grout": (0.0, 0.3, False),
           "blotch": (0.01, 0.5, False), "scale_m": (0.25, 200.0, False),
           "courses": (2, 64, True), "ratio": (1, 8, True), "joint": (0.0, 0.3, False)}


def _zone(z, where):
    if not isinstance(z, dict) or "family" not in z:
        raise ValueError(f"{where}: expected a dict with a 'family' field, got {z!r}")
    fam = z["family"]
    if fam not in FAMILIES:
        raise ValueError(f"{where}.family: unknown ground family {fam!r}; valid: {', '.join(FAMILIES)}")
    defaults = FAMILIES[fam][2]
    _check_fields(z, set(defaults) | {"family", "scale_m"}, where)
    out = {"family": fam, "scale_m": FAMILIES[fam][1]}
    out.update(copy.deepcopy(defaults))
    for k, v in z.items():
        if k == "family":
            continue
        if k in ("colour", "colour2"):
            out[k] = _colour(v, f"{where}.{k}")
        elif k == "stone_px":
            if not (isinstance(v, (list, tuple)) and len(v) == 2):
                raise ValueError(f"{where}.stone_px: expected [min, max] radii in texels, got {v!r}")
            lo, hi = (_number(x, f"{where}.stone_px", 1, 64, integer=True) for x in v)
            if lo > hi:
                raise ValueError(f"{where}.stone_px: expected min <= max, got {v!r}")
            out[k] = [lo, hi]
        else:
            lo, hi, integer = _LIMITS[k]
            out[k] = _number(v, f"{where}.{k}", lo, hi, integer)
    if fam == "pavers" and out["courses"] % out["ratio"]:
        raise ValueError(f"{where}.courses: expected a multiple of ratio ({out['ratio']}) so that the bricks "
                         f"tile, got {out['courses']}")
    return out


def _sky(s, where="appearance.sky"):
    if not isinstance(s, dict) or "kind" not in s:
        raise ValueError(f"{where}: expected a dict with a 'kind' field, got {s!r}")
    kind = s["kind"]
    if kind not in SKIES:
        raise ValueError(f"{where}.kind: unknown sky kind {kind!r}; valid: {', '.join(SKIES)}")
    _check_fields(s, set(SKIES[kind]) | {"kind"}, where)
    out = {"kind": kind, **copy.deepcopy(SKIES[kind])}
    for k, v in s.items():
        if k in ("colour", "colour2", "clutter_colour"):
            out[k] = _colour(v, f"{where}.{k}")
        elif k == "clutter_deg":
            out[k] = _number(v, f"{where}.{k}", 0.0, 30.0)
    return out


def _light(li, where="appearance.light"):
    _check_fields(li, LIGHT_FIELDS, where)
    out = copy.deepcopy(LIGHT_FIELDS)
    for k, v in li.items():
        if k == "colour":
            out[k] = _colour(v, f"{where}.colour", hi=1.0)
        else:
            lo, hi = {"intensity": (0.0, 4.0), "azimuth_deg": (-360.0, 360.0), "elevation_deg": (1.0, 90.0),
                      "ambient": (0.0, 1.0)}[k]
            out[k] = _number(v, f"{where}.{k}", lo, hi)
    return out


def resolve_appearance(appearance, seed):
    """The full explicit spec of an ``appearance`` option (None for the default scene).

    An explicit spec is a dict with the optional fields ``ground`` (a list of 1-16 zone dicts laid
    out along the route in contiguous arcs, in order; one dict is one zone for the whole route), ``sky``, ``light`` and
    ``texture_seed`` (int; default: drawn from ``seed``). A zone has ``family`` and that family's
    options (:data:`FAMILIES`) plus ``scale_m``, the texture repeat in metres; a sky has ``kind`` and
    its fields (:data:`SKIES`); light fields are :data:`LIGHT_FIELDS`. Missing fields take the
    defaults; a missing ``ground`` keeps the default zones' textures, a missing ``sky``/``light``
    the default scene's. Unknown names raise ``ValueError`` listing the valid ones.
    """
    if appearance is None:
        return None
    if isinstance(appearance, str):
        if appearance == "random":
            return resolve_appearance(sample_appearance(seed), seed)
        if appearance in FAMILIES:
            return resolve_appearance(sample_appearance(seed, appearance), seed)
        raise ValueError(f"appearance: unknown appearance {appearance!r}; valid: None, 'random', "
                         f"a family ({', '.join(FAMILIES)}) or an explicit spec (dict)")
    if not isinstance(appearance, dict):
        raise ValueError(f"appearance: expected None, 'random', a family name or a dict, got {type(appearance).__name__}")
    _check_fields(appearance, {"ground", "sky", "light", "texture_seed"}, "appearance")
    out = {}
    g = appearance.get("ground")
    if g is not None:
        if isinstance(g, dict):
            g = [g]
        if not isinstance(g, (list, tuple)) or not 1 <= len(g) <= 16:
            raise ValueError(f"appearance.ground: expected a zone dict or a list of 1-16 of them, got {g!r}")
        out["ground"] = [_zone(z, f"appearance.ground[{i}]") for i, z in enumerate(g)]
    if appearance.get("sky") is not None:
        out["sky"] = _sky(appearance["sky"])
    if appearance.get("light") is not None:
        out["light"] = _light(appearance["light"])
    ts = appearance.get("texture_seed")
    if ts is None:
        ts = int(np.random.default_rng(np.random.SeedSequence([int(seed), 7004])).integers(0, 2**31 - 1))
    out["texture_seed"] = _number(ts, "appearance.texture_seed", 0, 2**63 - 1, integer=True)
    return out
