"""The synthetic RGB-D renderer used by the tracking tests and benchmarks."""

import numpy as np
import trimesh

from polar_sim.tracking.synthetic import TARGET, make_sequence


def test_rendered_depth_lies_on_the_posed_mesh():
    # back-projected clean depth of the target lies on the mesh (median < 0.5 mm)
    seq = make_sequence(1, "box", hand=False, noise=False)
    f = seq.frame(0)
    v, u = np.nonzero(f["labels"] == TARGET)
    z = f["depth_clean"][v, u].astype(float)
    K = seq.K
    X = np.stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z], 1)
    mesh = seq.target.mesh
    mesh.apply_transform(seq.poses[0])
    _, dist, _ = trimesh.proximity.closest_point(mesh, X[::7])
    assert np.median(dist) < 5e-4


def test_frames_are_deterministic_and_noisy():
    # same seed, same frame bit for bit; noise changes depth but not the truth masks
    a = make_sequence(3, "mug").frame(2)
    b = make_sequence(3, "mug").frame(2)
    assert np.array_equal(a["rgb"], b["rgb"]) and np.array_equal(a["depth"], b["depth"])
    assert a["hand"].any() and a["mask"].any()
    valid = a["depth"] > 0
    assert not np.array_equal(a["depth"][valid], a["depth_clean"][valid])


def test_hidden_and_occluded_frames():
    # hidden frames show no target; occluded frames hide it behind a board
    seq = make_sequence(3, "mug", hidden={1}, occluded={2})
    assert not seq.frame(1)["mask"].any()
    assert not seq.frame(2)["mask"].any() and seq.frame(0)["mask"].any()
