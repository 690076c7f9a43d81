"""The object catalogue: closed outward meshes, small reproducible assets, the frame convention,
and MuJoCo loading exactly the shipped meshes."""

import numpy as np
import pytest
import trimesh

from polar_sim.sim.builders import objects as O


@pytest.mark.parametrize("name", O.object_names())
def test_mesh_is_closed_and_outward(name):
    # Every shipped mesh is watertight, consistently wound, with positive volume and outward normals.
    m = O.load_mesh(name)
    assert m.is_watertight and m.is_winding_consistent
    assert m.volume > 0
    pts, face = trimesh.sample.sample_surface(m, 300, seed=1)
    n = m.face_normals[face]
    # (a point 1 mm out of a face can fall inside the object next to a concave edge: hence "most")
    assert m.contains(pts + 1e-3 * n).mean() < 0.02
    assert m.contains(pts - 5e-4 * n).mean() > 0.95  # thin walls (mug 4.5 mm) included


@pytest.mark.parametrize("name", O.object_names())
def test_object_frame_and_size(name):
    # The object frame sits on the base (lowest point at z = 0); sizes are tabletop-object sizes.
    m = O.load_mesh(name)
    assert m.bounds[0, 2] == pytest.approx(0.0, abs=1e-6)
    assert 0.05 < O.diameter(m) < 0.3
    assert O.asset_path(name).stat().st_size < 200_000


def test_catalogue_is_varied():
    # At least 5 objects of distinct sizes, two of them non-convex, with collision primitives.
    names = O.object_names()
    assert len(names) >= 5 and {"mug", "box", "can", "bottle"} <= set(names)
    d = [O.diameter(O.load_mesh(n)) for n in names]
    assert len(set(np.round(d, 3))) == len(d)
    nonconvex = [n for n in names if O.load_mesh(n).volume < 0.97 * O.load_mesh(n).convex_hull.volume]
    assert {"mug", "drill"} <= set(nonconvex)
    assert all(O.object_info(n).collision for n in names)


def test_unknown_object_lists_valid_names():
    # A bad object name raises ValueError naming the valid ones.
    with pytest.raises(ValueError, match="mug"):
        O.object_info("banana")


def test_assets_regenerate_identically(tmp_path):
    # `python -m polar_sim.sim.builders.objects` reproduces the shipped OBJ files byte for byte (manifold3d is in
    # the test extra: the composite objects need its boolean unions).
    for p in O.write_assets(tmp_path):
        assert p.read_bytes() == O.asset_path(p.stem).read_bytes(), p.name


def test_mujoco_loads_the_shipped_meshes():
    # The compiled scene's object meshes equal the OBJ files (up to float32), and World.object_points
    # samples them with outward normals, in the object frame.
    from polar_sim.sim import World

    w = World("tabletop", seed=3, n_objects=6, script="touch")
    try:
        for name in w.meta.objects:
            mj = w.object_mesh(name)
            ref = O.load_mesh(name)
            _, dist, _ = trimesh.proximity.closest_point(ref, np.asarray(mj.vertices)[::7])
            assert dist.max() < 1e-6, name
            pts, nrm = w.object_points(name, 200, seed=2)
            assert ref.contains(pts + 1e-3 * nrm).mean() < 0.02, name
    finally:
        w.close()
