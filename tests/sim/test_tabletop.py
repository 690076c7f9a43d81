"""tabletop and object_orbit against exact ground truth (tracking spec Sec. 9.7): depth on the
posed mesh, silhouette vs amodal mask, labels, the scene SDF, scripted contact, determinism, and
the sequence suite."""

import numpy as np
import pytest
import trimesh

from polar_sim.geometry import inv_pose, transform_points
from polar_sim.sim import World
from polar_sim.sim.builders import objects as O
from polar_sim.sim.recorders.tabletop_sequences import SEQUENCES, record_sequence
from polar_sim.sim.truth import LABELS

W, H = 320, 240


def _backproject(depth, K, mask):
    v, u = np.nonzero(mask)
    z = depth[v, u].astype(np.float64)
    return np.stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z], 1)


def _rasterise(uv, faces, h, w):
    """Pixels (h, w) bool whose centres fall inside a projected triangle (OpenCV pixel centres)."""
    out = np.zeros((h, w), bool)
    for a, b, c in uv[faces]:
        lo = np.maximum(np.ceil(np.minimum(np.minimum(a, b), c)), 0).astype(int)
        hi = np.minimum(np.floor(np.maximum(np.maximum(a, b), c)), [w - 1, h - 1]).astype(int)
        if (hi < lo).any():
            continue
        x, y = np.meshgrid(np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1))
        e = [(q[0] - p[0]) * (y - p[1]) - (q[1] - p[1]) * (x - p[0]) for p, q in ((a, b), (b, c), (c, a))]
        inside = ((e[0] >= 0) & (e[1] >= 0) & (e[2] >= 0)) | ((e[0] <= 0) & (e[1] <= 0) & (e[2] <= 0))
        out[lo[1] : hi[1] + 1, lo[0] : hi[0] + 1] |= inside
    return out


@pytest.fixture(scope="module")
def held():
    """The mug held by the hand (lift script, tilting), one 320x240 frame with its truth."""
    w = World("tabletop", seed=0, script="lift", target="mug")
    while w.truth()["phase"] != "tilt":
        w.step()
    for _ in range(10):
        w.step()
    f = w.camera("rgbd", width=W, height=H)
    full = w.amodal_mask("rgbd", width=W, height=H)
    tr = w.truth()
    hand_geoms = {g for g in range(w.model.ngeom) if w.model.body(w.model.geom_bodyid[g]).name == "hand"}
    mug_geoms = {g for g in range(w.model.ngeom) if w.model.geom_bodyid[g] == w.model.body("mug").id}
    w.close()
    return f, full, tr, hand_geoms, mug_geoms


def test_depth_lies_on_posed_mesh(held):
    # Clean depth of the visible target, back-projected with K and T_cam_obj, lies on the mesh.
    f, full, tr, _, _ = held
    T_co = inv_pose(f.T_world_cam) @ tr["objects"]["mug"]
    P = transform_points(inv_pose(T_co), _backproject(f.depth, f.K, f.labels == LABELS["target"]))
    _, d, _ = trimesh.proximity.closest_point(O.load_mesh("mug"), P)
    assert len(d) > 300
    assert np.median(d) < 5e-4 and np.percentile(d, 99) < 5e-4


def test_projected_silhouette_matches_amodal_mask(held):
    # The mesh projected under the true pose covers exactly the amodal mask (pixel-centre
    # rasterisation, as OpenGL's): IoU > 0.99, stricter than the spec's 0.98.
    f, full, tr, _, _ = held
    mesh = O.load_mesh("mug")
    V = transform_points(inv_pose(f.T_world_cam) @ tr["objects"]["mug"], mesh.vertices)
    uv = V[:, :2] / V[:, 2:] * np.diag(f.K)[:2] + f.K[:2, 2]
    sil = _rasterise(uv, mesh.faces, H, W)
    assert (sil & full).sum() / (sil | full).sum() > 0.99


def test_amodal_contains_visible_and_hand_occludes(held):
    # amodal ⊇ visible; the hand is labelled occluder, the mug target, each from its own geoms.
    f, full, tr, hand_geoms, mug_geoms = held
    vis = f.labels == LABELS["target"]
    occ = f.labels == LABELS["occluder"]
    assert not (vis & ~full).any()
    assert 0.05 < 1 - vis.sum() / full.sum() < 0.8
    assert occ.sum() > 500 and (occ & full).any()
    assert set(np.unique(f.geom_ids[occ])) <= hand_geoms
    assert set(np.unique(f.geom_ids[vis])) <= mug_geoms
    assert tr["grasped"] and tr["in_contact"] and tr["target"] == "mug"


def test_held_object_moves_rigidly_with_hand():
    # Mode A: while held, T_hand^-1 T_obj is constant and the object follows the script exactly.
    w = World("tabletop", seed=1, script="lift", target="box")
    rel = []
    for _ in range(240):
        w.step()
        tr = w.truth()
        if tr["grasped"]:
            rel.append(inv_pose(tr["hand_pose"]) @ tr["objects"]["box"])
    w.close()
    assert len(rel) > 100
    assert np.abs(np.array(rel) - rel[0]).max() < 1e-9


def test_object_orbit_depth_on_static_scene_sdf():
    # object_orbit: the object is static, so World.sdf includes it; depth lands on it (< 2 mm),
    # and object_points (object frame) map onto the zero level set with outward normals.
    w = World("object_orbit", seed=0, object="mug", radius=0.6)
    for _ in range(40):
        w.step()
    f = w.camera("rgbd", width=W, height=H)
    assert (f.labels == LABELS["target"]).sum() > 1000
    ok = np.isfinite(f.depth)
    Pw = transform_points(f.T_world_cam, _backproject(f.depth, f.K, ok))
    tgt = (f.labels[ok] == LABELS["target"])
    rng = np.random.default_rng(0)
    idx = np.concatenate([rng.choice(np.flatnonzero(tgt), 300, replace=False),
                          rng.choice(np.flatnonzero(~tgt), 300, replace=False)])
    assert np.abs(w.sdf(Pw[idx])).max() < 2e-3
    T_wo = w.truth()["objects"]["mug"]
    pts, nrm = w.object_points("mug", 300, seed=1)
    assert np.abs(w.sdf(transform_points(T_wo, pts))).max() < 1e-5
    up = nrm[:, 2] > -0.9  # the base rests on the stand, whose inside is negative too
    d_out = w.sdf(transform_points(T_wo, pts[up] + 1e-3 * nrm[up]))
    assert np.mean(d_out > 5e-4) > 0.98
    w.close()


def test_touch_makes_contact_without_moving_the_object():
    # touch: the palm rests on the target (contact in every touch frame); it barely moves.
    w = World("tabletop", seed=2, script="touch", target="can")
    p0 = w.truth()["objects"]["can"][:, 3].copy()
    phases = []
    for _ in range(200):
        w.step()
        tr = w.truth()
        phases.append((tr["phase"], tr["in_contact"]))
    touch = [c for p, c in phases if p == "touch"]
    assert len(touch) > 30 and all(touch)
    assert np.linalg.norm(w.truth()["objects"]["can"][:3, 3] - p0[:3]) < 2e-3
    w.close()


def test_push_moves_the_object_by_physics():
    # push: the fingers touch the target and it slides about 10 cm along +x.
    w = World("tabletop", seed=0, script="push", target="box")
    p0 = w.truth()["objects"]["box"][:3, 3].copy()
    contact = 0
    for _ in range(230):
        w.step()
        contact += w.truth()["in_contact"]
    d = w.truth()["objects"]["box"][:3, 3] - p0
    w.close()
    assert contact > 20
    assert 0.06 < d[0] < 0.14 and abs(d[2]) < 2e-3


def test_pass_never_touches_and_light_ramps():
    # pass: the hand crosses in front without any contact; light: the key light dims to 30 %.
    w = World("tabletop", seed=0, script="pass", target="box")
    assert not any(w.step() or w.truth()["in_contact"] for _ in range(330))
    w.close()
    w = World("tabletop", seed=0, script="light", target="bottle")
    key = w.model.light("key").id
    base = w.model.light_diffuse[key].copy()
    while w.time < 5.0:
        w.step()
    assert w.truth()["light_scale"] == pytest.approx(0.3)
    assert np.allclose(w.model.light_diffuse[key], 0.3 * base)
    w.reset()
    assert np.allclose(w.model.light_diffuse[key], base)
    w.close()


def test_reset_replays_the_script_exactly():
    # reset() restores the initial state: the same poses step by step.
    w = World("tabletop", seed=4, script="push")
    tgt = w.meta.target
    a = [(w.step(), w.truth()["objects"][tgt])[1] for _ in range(150)]
    w.reset()
    b = [(w.step(), w.truth()["objects"][tgt])[1] for _ in range(150)]
    w.close()
    assert np.array_equal(np.array(a), np.array(b))


def test_recorded_sequence_is_deterministic_and_cached(tmp_path, monkeypatch):
    # Same name and seed: byte-identical frames; the cached recording (polar_sim.sim.recorders.sequences) reads
    # back identical, frame by frame, and a second call reads the cache instead of recording
    from polar_sim.sim.recorders.tabletop_sequences import cached_sequence

    monkeypatch.setenv("POLAR_SIM_CACHE", str(tmp_path))
    a = record_sequence("mug_touch", seed=0, n_frames=3, width=160, height=120)
    b = record_sequence("mug_touch", seed=0, n_frames=3, width=160, height=120)
    c = cached_sequence("mug_touch", seed=0, n_frames=3, width=160, height=120)
    assert a.keys == b.keys and set(a.keys) == set(c.keys)
    for k in a.keys:
        assert np.array_equal(a.stack(k), b.stack(k)) and np.array_equal(a.stack(k), c.stack(k)), k
    files = list((tmp_path / "tabletop").glob("*.npz"))
    assert len(files) == 1
    mtime = files[0].stat().st_mtime_ns
    d = cached_sequence("mug_touch", seed=0, n_frames=3, width=160, height=120)
    assert files[0].stat().st_mtime_ns == mtime and len(d) == 3
    assert c.meta["object"] == a.meta["object"] == "mug" and np.array(a.meta["K"]).shape == (3, 3)
    f = a[2]
    missing = ~np.isfinite(f["depth"])
    assert missing.mean() > 0.005 and np.isfinite(f["depth_clean"]).all()
    assert not np.array_equal(f["depth"][~missing], f["depth_clean"][~missing])
    assert f["T_cam_obj"].shape == (4, 4) and f["mask_full"].dtype == bool


@pytest.mark.parametrize("name", ["drill_orbit", "blocks_turn_flat", "blocks_push_gloved"])
def test_every_kind_of_sequence_records_from_an_empty_cache(name, tmp_path, monkeypatch):
    # a dev orbit (object_orbit: no appearance option), a dev appearance family and a test sequence record
    # their first frames into an empty cache; the header says the split and appearance where there is one
    monkeypatch.setenv("POLAR_SIM_CACHE", str(tmp_path))
    rec = record_sequence(name, seed=0 if name != "blocks_push_gloved" else 10_000, n_frames=2, width=64, height=48)
    assert len(rec) == 2 and rec[1]["T_cam_obj"].shape == (4, 4)
    assert ("appearance" in rec.meta) == (name != "drill_orbit"), rec.meta.keys()


def test_sequence_suite_covers_the_brief():
    # At least 12 sequences of 300-600 frames over at least 4 objects, with every kind of event.
    assert len(SEQUENCES) >= 12
    assert all(300 <= s.frames <= 600 for s in SEQUENCES.values())
    objs = {s.options.get("target") or s.options.get("object") for s in SEQUENCES.values()}
    assert len(objs) >= 4
    scripts = {s.options.get("script") for s in SEQUENCES.values()}
    assert {"touch", "push", "lift", "turn", "fast", "light", "pass"} <= scripts
    with pytest.raises(ValueError, match="mug_touch"):
        record_sequence("no_such_sequence")


@pytest.mark.parametrize("scene, options, valid", [
    ("tabletop", {"script": "dance"}, "touch"),
    ("tabletop", {"target": "banana"}, "mug"),
    ("tabletop", {"n_objects": 9}, "4..6"),
    ("tabletop", {"camera_motion": "spin"}, "sway"),
    ("tabletop", {"target_colour": "plaid"}, "skin"),
    ("tabletop", {"speed": 2}, "script"),
    ("object_orbit", {"object": "banana"}, "drill"),
    ("object_orbit", {"radius": 3.0}, "0.5"),
])
def test_bad_scene_options_raise(scene, options, valid):
    # A bad option value or name raises ValueError naming what is valid.
    with pytest.raises(ValueError, match=valid):
        World(scene, seed=0, **options)


# -- appearance (issue 13): families, explicit specs, and the truth they must not change -------------

def _frames(seed, appearance, target="blocks", script="touch", n=75):
    w = World("tabletop", seed=seed, script=script, target=target, appearance=appearance)
    for _ in range(n):
        w.step()
    f = w.camera("rgbd", width=W, height=H)
    full = w.amodal_mask("rgbd", width=W, height=H)
    out = dict(f=f, full=full, meta=w.meta, model=w.model, truth=w.truth())
    out["hand_geoms"] = {g for g in range(w.model.ngeom) if w.model.body(w.model.geom_bodyid[g]).name == "hand"}
    out["target_geoms"] = {g for g in range(w.model.ngeom) if w.model.geom_bodyid[g] == w.model.body(target).id}
    w.close()
    return out


@pytest.fixture(scope="module")
def looks():
    """Seed 5, the palm on the blocks object, under no appearance and every family."""
    return {a: _frames(5, a) for a in (None, "default", "textured", "flat", "gloved", "studio", "random")}


def test_default_appearance_renders_as_before(looks):
    # "default" is the scene as it has always been: the same bytes as no appearance at all
    a, b = looks[None]["f"], looks["default"]["f"]
    for k in ("rgb", "depth", "labels", "geom_ids"):
        assert np.array_equal(getattr(a, k), getattr(b, k)), k


def test_appearance_changes_colours_only(looks):
    # every family keeps the seed's layout and motion: depth, labels, geom ids and the amodal mask are
    # identical to the default's bit for bit, while the colours differ
    ref = looks[None]
    for a, x in looks.items():
        if a in (None, "default"):
            continue
        for k in ("depth", "labels", "geom_ids"):
            assert np.array_equal(getattr(x["f"], k), getattr(ref["f"], k)), (a, k)
        assert np.array_equal(x["full"], ref["full"]), a
        assert np.abs(x["f"].rgb.astype(int) - ref["f"].rgb).mean() > 3, a
        assert x["meta"].appearance["family"] == a


def test_labels_come_from_geoms_under_every_appearance(looks):
    # target pixels come only from the target's geoms and occluder pixels only from the hand's (a glove too)
    for a, x in looks.items():
        f = x["f"]
        vis, occ = f.labels == LABELS["target"], f.labels == LABELS["occluder"]
        assert vis.sum() > 500 and occ.sum() > 300, a
        assert set(np.unique(f.geom_ids[vis])) <= x["target_geoms"], a
        assert set(np.unique(f.geom_ids[occ])) <= x["hand_geoms"], a
        assert not (vis & ~x["full"]).any(), a


def test_blocks_depth_and_silhouette_are_exact(looks):
    # the three-part object: clean depth back-projects onto its mesh (< 0.5 mm) and the projected mesh
    # covers the amodal mask (IoU > 0.99)
    x = looks["flat"]
    f, full = x["f"], x["full"]
    T_co = inv_pose(f.T_world_cam) @ x["truth"]["objects"]["blocks"]
    mesh = O.load_mesh("blocks")
    P = transform_points(inv_pose(T_co), _backproject(f.depth, f.K, f.labels == LABELS["target"]))
    _, d, _ = trimesh.proximity.closest_point(mesh, P)
    assert len(d) > 300 and np.percentile(d, 99) < 5e-4
    V = transform_points(T_co, mesh.vertices)
    sil = _rasterise(V[:, :2] / V[:, 2:] * np.diag(f.K)[:2] + f.K[:2, 2], mesh.faces, H, W)
    assert (sil & full).sum() / (sil | full).sum() > 0.99


def _texture(model, name):
    t = model.texture(name)
    return model.tex_data[t.adr[0]: t.adr[0] + t.height[0] * t.width[0] * 3].reshape(t.height[0], t.width[0], 3)


def test_explicit_spec_sets_flat_part_colours_hand_and_light():
    # {"colours": ...} with flat objects: each atlas tile of the blocks object is exactly one named colour;
    # the hand is the named glove; the key light is turned and scaled as asked
    from polar_sim.sim.builders.tabletop import COLOURS
    from polar_sim.sim.builders.tabletop_appearance import HAND_COLOURS

    spec = {"objects": "flat", "hand": "glove_black", "colours": {"blocks": ["blue", "yellow", "red"]},
            "light": {"intensity": 0.5, "azimuth_deg": 90.0}}
    w = World("tabletop", seed=5, script="touch", target="blocks", appearance=spec)
    ref = World("tabletop", seed=5, script="touch", target="blocks")
    try:
        img = _texture(w.model, "tex_blocks")
        h = img.shape[0] // 2
        for k, c in enumerate(["blue", "yellow", "red"]):
            tile = img[(k // 2) * h:(k // 2 + 1) * h, (k % 2) * h:(k % 2 + 1) * h].reshape(-1, 3)
            assert (tile == np.array(COLOURS[c], np.uint8)).all(), c
        palm = w.model.geom("hand_palm").id
        assert np.allclose(w.model.geom_rgba[palm, :3], HAND_COLOURS["glove_black"])
        k0, k1 = ref.model.light("key").id, w.model.light("key").id
        p0 = ref.model.light_pos[k0]
        assert np.allclose(w.model.light_pos[k1], [-p0[1], p0[0], p0[2]], atol=1e-9)
        assert np.allclose(w.model.light_diffuse[k1], 0.5 * ref.model.light_diffuse[k0])
        assert w.meta.colours["blocks"] == ["blue", "yellow", "red"]
    finally:
        w.close()
        ref.close()


def test_appearance_is_seeded():
    # the same seed and family give the same choices; another seed gives other choices
    from polar_sim.sim.builders.tabletop_appearance import resolve_appearance

    a, b = resolve_appearance("random", 3), resolve_appearance("random", 3)
    assert a == b
    assert any(resolve_appearance("random", s) != a for s in range(4, 8))
    assert resolve_appearance(None, 0) is None


@pytest.mark.parametrize("appearance, match", [
    ("velvet", "unknown family 'velvet'.*'studio'"),
    ({"colour": "red"}, "unknown field.*'colour'.*'hand'"),
    ({"hand": "purple"}, "field 'hand'.*glove_blue"),
    ({"table": "glass"}, "field 'table'.*marble"),
    ({"objects": "shiny"}, "field 'objects'.*flat"),
    ({"light": {"intensity": 9.0}}, "field 'light.intensity'"),
    ({"light": {"hue": 1.0}}, "field 'light'.*hue"),
    ({"light": {"tint": [1, 1]}}, "field 'light.tint'"),
    ({"colours": {"banana": ["red"]}}, "field 'colours'.*banana"),
    ({"colours": {"box": ["plaid"]}}, "field 'colours.box'"),
    ({"family": "nope"}, "field 'family'"),
    (7, "dict spec"),
])
def test_bad_appearance_raises(appearance, match):
    # an unknown family or field, or a malformed value, raises ValueError naming it and what is valid
    with pytest.raises(ValueError, match=match):
        World("tabletop", seed=0, appearance=appearance)


def test_test_split_sequences_are_held_out():
    # the test split: seeds >= 10,000, untextured and multi-part objects, held-out appearance families only
    from polar_sim.sim.builders.tabletop_appearance import DEV_FAMILIES, TEST_FAMILIES
    from polar_sim.sim.recorders.tabletop_sequences import SPLIT_SEEDS, TEST_SEQUENCES, list_sequences

    assert len(list_sequences("test")) >= 10 and min(SPLIT_SEEDS["test"]) >= 10_000
    assert list_sequences("dev") == list(SEQUENCES) and SPLIT_SEEDS["dev"] == (0,)
    assert not set(TEST_SEQUENCES) & set(SEQUENCES)
    fams = set()
    for s in TEST_SEQUENCES.values():
        a = s.options["appearance"]
        fams.add(a if isinstance(a, str) else a.get("family", "default"))
        assert 300 <= s.frames <= 600
    assert fams <= set(TEST_FAMILIES) | {"random"} and not fams & set(DEV_FAMILIES)
    assert "blocks" in {s.options["target"] for s in TEST_SEQUENCES.values()}
    assert {"touch", "pass"} & {s.options["script"] for s in TEST_SEQUENCES.values()}  # static targets
