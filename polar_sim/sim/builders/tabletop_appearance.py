"""Seeded appearance of the ``tabletop`` scene: object surfaces, hand colour, table texture, light.

``World("tabletop", seed=s, appearance=A)`` with ``A`` one of

* ``None`` (the default): the scene exactly as it has always been rendered (every earlier
  recording stays valid);
* a family name (:data:`FAMILIES`), whose choices are drawn from the seed: ``"default"``,
  ``"textured"``, ``"flat"`` (the families the tracker was tuned on: the ``dev`` families) and
  ``"gloved"``, ``"studio"`` (never used while tuning: the ``test`` families);
* ``"random"``: every field drawn independently from all of its options;
* an explicit spec (dict) with any of the fields below; ``"family"`` names the family the
  missing fields are drawn from (``"default"`` if absent).

=============  ================================================================================
field          values
=============  ================================================================================
objects        ``"textured"`` (the printed atlas: mottled body, stripes, label, dark parts),
               ``"flat"`` (untextured: every part one uniform colour; ``blocks`` shows three
               colours), ``"mixed"`` (each object textured or flat, drawn from the seed)
hand           a name of :data:`HAND_COLOURS`: five skin tones and four gloves
sleeve         a name of :data:`SLEEVE_COLOURS`
table          a name of :data:`TABLE_TEXTURES`
light          ``{"intensity", "azimuth_deg", "tint", "fill", "ambient"}``: the key light's
               diffuse scale (0.2-2), its rotation about the vertical through the table centre
               (deg, -180..180), an RGB multiplier of it (each 0.5-1.5), the fill light's scale
               (0-2) and the headlight's ambient level (0-0.6)
colours        ``{object name: [c0, c1, c2]}``: colour names (:data:`~polar_sim.sim.builders.tabletop_textures.COLOURS`)
               of an object's body, accent and third part (the label tile; ``blocks``' small block)
=============  ================================================================================

The choices are drawn from the seed, the family and the scene's script and target (so one seed
gives different looks to different scripts). The scene's layout (which objects, where, which
yaw) is drawn from the seed exactly as without an appearance, from a separate random stream: one seed gives the same table under every appearance,
so the label renders (target, occluder, amodal masks) and the depth are identical, and only the
colours change. All textures are procedural (no shipped images).
"""

from __future__ import annotations

import dataclasses
import numbers
import zlib

import numpy as np

__all__ = ["AppearanceSpec", "FAMILIES", "DEV_FAMILIES", "TEST_FAMILIES", "HAND_COLOURS", "SLEEVE_COLOURS",
           "TABLE_TEXTURES", "OBJECT_STYLES", "resolve_appearance", "table_texture", "flat_texture",
           "describe_families"]

#: Hand colours (RGB 0..1): skin tones from light to dark, and four gloves. ``skin_medium`` is the
#: default scene's hand.
HAND_COLOURS = {
    "skin_light": (0.96, 0.80, 0.69), "skin_medium": (0.87, 0.66, 0.53), "skin_tan": (0.76, 0.56, 0.40),
    "skin_brown": (0.55, 0.37, 0.25), "skin_dark": (0.34, 0.22, 0.15),
    "glove_blue": (0.22, 0.42, 0.86), "glove_black": (0.07, 0.07, 0.08), "glove_white": (0.90, 0.91, 0.89),
    "glove_green": (0.24, 0.60, 0.34),
}
SKIN_TONES = tuple(k for k in HAND_COLOURS if k.startswith("skin"))
GLOVES = tuple(k for k in HAND_COLOURS if k.startswith("glove"))
#: Sleeve (forearm) colours, RGB 0..1; ``navy`` is the default scene's.
SLEEVE_COLOURS = {"navy": (0.22, 0.30, 0.48), "grey": (0.45, 0.45, 0.47), "red": (0.62, 0.16, 0.14),
                  "black": (0.10, 0.10, 0.11), "olive": (0.36, 0.38, 0.20)}
#: Procedural table textures.
TABLE_TEXTURES = ("wood", "plain", "speckle", "checker", "cloth", "marble")
OBJECT_STYLES = ("textured", "flat", "mixed")
FIELDS = ("objects", "hand", "sleeve", "table", "light", "colours")
LIGHT_FIELDS = {"intensity": (0.2, 2.0), "azimuth_deg": (-180.0, 180.0), "tint": (0.5, 1.5), "fill": (0.0, 2.0),
                "ambient": (0.0, 0.6)}
_DEFAULT_LIGHT = {"intensity": 1.0, "azimuth_deg": 0.0, "tint": (1.0, 1.0, 1.0), "fill": 1.0, "ambient": 0.25}


@dataclasses.dataclass(frozen=True)
class AppearanceSpec:
    """A concrete appearance: every choice made (what :func:`resolve_appearance` returns)."""

    family: str
    objects: str
    hand: str
    sleeve: str
    table: str
    light: dict
    colours: dict

    def as_dict(self):
        """JSON-able form (the ``appearance`` entry of the scene's metadata)."""
        d = dataclasses.asdict(self)
        d["light"] = {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.light.items()}
        return d


def _u(lo, hi):
    return lambda rng: float(rng.uniform(lo, hi))


def _pick(options):
    return lambda rng: str(options[int(rng.integers(len(options)))])


def _tint(spread):
    def draw(rng):
        # a colour temperature (warm: more red, less blue) plus a little independent jitter
        w = rng.uniform(-spread, spread)
        return tuple(float(np.clip(v, 0.5, 1.5)) for v in (1 + w, 1.0, 1 - w) + rng.uniform(-0.03, 0.03, 3))
    return draw


def _side(lo, hi):
    return lambda rng: float(rng.choice([-1.0, 1.0]) * rng.uniform(lo, hi))


#: Families: for every field, a fixed value or a function of a Generator that draws one.
FAMILIES = {
    "default": dict(objects="textured", hand="skin_medium", sleeve="navy", table="wood",
                    light=dict(_DEFAULT_LIGHT), description="the scene as it has always been rendered"),
    "textured": dict(objects="textured", hand=_pick(SKIN_TONES), sleeve=_pick(tuple(SLEEVE_COLOURS)),
                     table=_pick(("wood", "plain", "speckle")),
                     light=dict(intensity=_u(0.7, 1.2), azimuth_deg=_u(-40, 40), tint=_tint(0.08),
                                fill=_u(0.7, 1.3), ambient=_u(0.18, 0.30)),
                     description="printed objects, any skin tone, wood / plain / speckle table, light jitter"),
    "flat": dict(objects="flat", hand=_pick(SKIN_TONES), sleeve=_pick(tuple(SLEEVE_COLOURS)),
                 table=_pick(("wood", "plain", "speckle")),
                 light=dict(intensity=_u(0.7, 1.2), azimuth_deg=_u(-40, 40), tint=_tint(0.08),
                            fill=_u(0.7, 1.3), ambient=_u(0.18, 0.30)),
                 description="untextured objects (one flat colour per part), any skin tone, light jitter"),
    "gloved": dict(objects="mixed", hand=_pick(GLOVES), sleeve=_pick(tuple(SLEEVE_COLOURS)),
                   table=_pick(("checker", "cloth")),
                   light=dict(intensity=_u(0.6, 1.3), azimuth_deg=_u(-70, 70), tint=_tint(0.12),
                              fill=_u(0.5, 1.5), ambient=_u(0.12, 0.35)),
                   description="a gloved hand, textured and flat objects mixed, checker / cloth table"),
    "studio": dict(objects="flat", hand=_pick(("skin_light", "skin_brown", "skin_dark")),
                   sleeve=_pick(tuple(SLEEVE_COLOURS)), table=_pick(("marble", "checker", "plain")),
                   light=dict(intensity=_u(0.5, 1.4), azimuth_deg=_side(50, 110), tint=_tint(0.18),
                              fill=_u(0.3, 1.0), ambient=_u(0.10, 0.30)),
                   description="untextured objects, light or dark skin, marble / checker / plain table, "
                               "a coloured side light"),
}
#: Families used while tuning the tracker (``dev``) and never used while tuning (``test``).
DEV_FAMILIES = ("default", "textured", "flat")
TEST_FAMILIES = ("gloved", "studio")
_RANDOM = dict(objects=_pick(OBJECT_STYLES), hand=_pick(tuple(HAND_COLOURS)), sleeve=_pick(tuple(SLEEVE_COLOURS)),
               table=_pick(TABLE_TEXTURES),
               light=dict(intensity=_u(0.5, 1.4), azimuth_deg=_u(-110, 110), tint=_tint(0.18), fill=_u(0.3, 1.5),
                          ambient=_u(0.10, 0.35)))


def describe_families():
    """{family: one-line description} (``random`` included)."""
    out = {k: v["description"] for k, v in FAMILIES.items()}
    out["random"] = "every field drawn independently from all of its options"
    return out


def _valid_names():
    return ", ".join(repr(k) for k in list(FAMILIES) + ["random"])


def _draw(value, rng):
    return value(rng) if callable(value) else value


def _check_name(value, choices, field):
    if not isinstance(value, str) or value not in choices:
        raise ValueError(f"appearance: field {field!r}: unknown value {value!r}; expected one of "
                         f"{', '.join(map(repr, choices))}")
    return value


def _check_light(light):
    if not isinstance(light, dict):
        raise ValueError(f"appearance: field 'light': expected a dict with keys {sorted(LIGHT_FIELDS)}, got {light!r}")
    unknown = sorted(set(light) - set(LIGHT_FIELDS))
    if unknown:
        raise ValueError(f"appearance: field 'light': unknown key(s) {unknown}; valid: {sorted(LIGHT_FIELDS)}")
    out = {}
    for k, v in light.items():
        lo, hi = LIGHT_FIELDS[k]
        vals = v if k == "tint" else (v,)
        if k == "tint" and (not isinstance(v, (list, tuple)) or len(v) != 3):
            raise ValueError(f"appearance: field 'light.tint': expected 3 numbers in [{lo}, {hi}], got {v!r}")
        for x in vals:
            if isinstance(x, bool) or not isinstance(x, numbers.Real) or not np.isfinite(x) or not lo <= x <= hi:
                raise ValueError(f"appearance: field 'light.{k}': expected a number in [{lo}, {hi}], got {v!r}")
        out[k] = tuple(float(x) for x in v) if k == "tint" else float(v)
    return out


def _check_colours(colours):
    from polar_sim.sim.builders.objects import OBJECTS
    from polar_sim.sim.builders.tabletop_textures import COLOURS

    if not isinstance(colours, dict):
        raise ValueError(f"appearance: field 'colours': expected {{object: [colour, ...]}}, got {colours!r}")
    out = {}
    for name, cs in colours.items():
        if name not in OBJECTS:
            raise ValueError(f"appearance: field 'colours': unknown object {name!r}; expected one of "
                             f"{', '.join(OBJECTS)}")
        if isinstance(cs, str) or not isinstance(cs, (list, tuple)) or not 1 <= len(cs) <= 3:
            raise ValueError(f"appearance: field 'colours.{name}': expected a list of 1-3 colour names, got {cs!r}")
        out[name] = [_check_name(c, tuple(COLOURS), f"colours.{name}") for c in cs]
    return out


def resolve_appearance(appearance, seed, context=""):
    """The concrete :class:`AppearanceSpec` of ``appearance`` for ``seed``, or None (the default scene).

    ``context`` (a string, e.g. the script and target) is mixed into the draws, so that scenes of
    one seed and family but different scripts or targets look different.

    Raises ``ValueError`` naming an unknown family (listing the valid ones), an unknown spec field
    (listing the valid fields) or a malformed field value.
    """
    if appearance is None:
        return None
    if isinstance(appearance, str):
        if appearance not in FAMILIES and appearance != "random":
            raise ValueError(f"appearance: unknown family {appearance!r}; expected one of {_valid_names()}, "
                             "or a dict spec")
        base, given, family = (_RANDOM if appearance == "random" else FAMILIES[appearance]), {}, appearance
    elif isinstance(appearance, dict):
        unknown = sorted(set(appearance) - set(FIELDS) - {"family"})
        if unknown:
            raise ValueError(f"appearance: unknown field(s) {unknown}; valid fields: {['family', *FIELDS]}")
        family = appearance.get("family", "default")
        if family not in FAMILIES and family != "random":
            raise ValueError(f"appearance: field 'family': unknown family {family!r}; expected one of {_valid_names()}")
        base = _RANDOM if family == "random" else FAMILIES[family]
        given = {k: v for k, v in appearance.items() if k != "family"}
        family = "custom"
    else:
        raise ValueError(f"appearance: expected None, a family name ({_valid_names()}) or a dict spec, "
                         f"got {type(appearance).__name__}")
    # the family's name is part of the seed: one seed draws differently in each family
    base_name = appearance if isinstance(appearance, str) else appearance.get("family", "default")
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 7104, zlib.crc32(base_name.encode()),
                                                        zlib.crc32(str(context).encode())]))
    # every field is drawn (in a fixed order) even when given, so a given field never shifts the others
    drawn = {k: _draw(base[k], rng) for k in ("objects", "hand", "sleeve", "table")}
    drawn["light"] = {k: _draw(base["light"].get(k, _DEFAULT_LIGHT[k]), rng) for k in LIGHT_FIELDS}
    spec = dict(drawn, colours={})
    for k, v in given.items():
        if k == "light":
            spec["light"] = dict(spec["light"], **_check_light(v))
        elif k == "colours":
            spec["colours"] = _check_colours(v)
    if "objects" in given:
        spec["objects"] = _check_name(given["objects"], OBJECT_STYLES, "objects")
    if "hand" in given:
        spec["hand"] = _check_name(given["hand"], tuple(HAND_COLOURS), "hand")
    if "sleeve" in given:
        spec["sleeve"] = _check_name(given["sleeve"], tuple(SLEEVE_COLOURS), "sleeve")
    if "table" in given:
        spec["table"] = _check_name(given["table"], TABLE_TEXTURES, "table")
    spec["light"]["tint"] = tuple(spec["light"]["tint"])
    return AppearanceSpec(family=family, **spec)


def appearance_rng(seed, context=""):
    """The random stream of the appearance's textures and per-object choices (apart from the layout's)."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), 7105, zlib.crc32(str(context).encode())]))


# -- textures --------------------------------------------------------------------------------

def _noise(rng, shape, sigma):
    from scipy.ndimage import gaussian_filter

    n = gaussian_filter(rng.standard_normal(shape), sigma, mode="wrap") if sigma > 0 else rng.standard_normal(shape)
    return n / (n.std() + 1e-9)


def table_texture(kind, rng, size=256):
    """A procedural table texture (size, size, 3) uint8 of ``kind`` (:data:`TABLE_TEXTURES`)."""
    from polar_sim.sim.builders.tabletop_textures import _wood_texture

    _check_name(kind, TABLE_TEXTURES, "table")
    if kind == "wood":
        return _wood_texture(rng, size)
    y, x = np.mgrid[0:size, 0:size] / size
    if kind == "plain":
        tone = np.array([(196, 192, 184), (150, 152, 156), (92, 110, 96), (226, 224, 218)][rng.integers(4)], float)
        img = tone + 1.5 * _noise(rng, (size, size), 1.0)[..., None]
    elif kind == "speckle":
        tone = np.array([150.0, 148.0, 142.0]) * rng.uniform(0.8, 1.15)
        img = tone + (22 * _noise(rng, (size, size), 0.0) + 6 * _noise(rng, (size, size), 3.0))[..., None]
    elif kind == "checker":
        n = int(rng.integers(6, 13))
        a, b = np.array([215.0, 212.0, 205.0]), np.array([60.0, 62.0, 70.0]) * rng.uniform(0.7, 1.5)
        sq = ((np.floor(x * n) + np.floor(y * n)) % 2)[..., None]
        img = a * (1 - sq) + b * sq + 3 * _noise(rng, (size, size), 1.0)[..., None]
    elif kind == "cloth":
        base = np.array([[150, 40, 40], [40, 70, 140], [60, 120, 70], [170, 150, 110]][rng.integers(4)], float)
        f = int(rng.integers(40, 70))
        weave = np.sin(2 * np.pi * f * x) * np.sin(2 * np.pi * f * y)
        img = base * (1 + 0.12 * weave[..., None]) + 5 * _noise(rng, (size, size), 0.7)[..., None]
    else:  # marble: large low-frequency blotches and thin veins
        blot = _noise(rng, (size, size), 24)
        vein = np.abs(np.sin(2 * np.pi * (3 * x + 2 * _noise(rng, (size, size), 10) * 0.25)))
        img = np.array([222.0, 218.0, 210.0]) - 28 * blot[..., None] - 50 * (vein < 0.06)[..., None]
    return np.clip(img, 0, 255).astype(np.uint8)


def flat_texture(colours, size=256):
    """An untextured atlas (size, size, 3) uint8: each 2x2 tile one flat colour.

    ``colours``: RGB 0..255 of the body, accent and third (label) tiles; the fourth (dark) tile is
    dark grey, as on the textured objects."""
    h = size // 2
    tiles = list(colours) + [(42, 42, 42)]
    img = np.zeros((size, size, 3), np.uint8)
    for k, c in enumerate(tiles[:4]):
        img[(k // 2) * h : (k // 2 + 1) * h, (k % 2) * h : (k % 2 + 1) * h] = np.clip(np.round(c), 0, 255)
    return img
