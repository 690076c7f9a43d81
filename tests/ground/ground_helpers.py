"""Helpers of the ground tests: truth constants of the shared sequence, a runner and the spec T4 scene."""

import numpy as np

#: Truth of the shared sequence: camera 1 m above a textured ground, 5 m/s, 0.1 rad/s, 10 Hz, 640x480.
SPEED, YAW_RATE, HEIGHT, DT = 5.0, 0.1, 1.0, 0.1


def run(vo, seq, frames=None):
    """Process ``frames`` (default all) of a sequence; returns the list of estimates."""
    idx = range(len(seq["times"])) if frames is None else frames
    return [vo.process(seq["rgb"][i], seq["times"][i]) for i in idx]


def t4_points(seed=0, wall_x=4.0, zmax=40.0):
    """Spec T4 scene: KITTI half-res camera, h = 1.68 m, V = 8 m/s, ω = 0.15 rad/s, 400 ground points and
    300 wall points (walls at x = ±wall_x, up to 3 m high), depths uniform in [5, zmax] m, all visible in
    the three frames t = -0.1, 0, +0.1 s of an exact unicycle path. Returns a dict of pixel positions
    (3, n, 2), the ground flag (n,), the true depths at t = 0 (n,) and the camera constants."""
    f, cu, cv, W, H = 359.428, 303.5964, 92.6079, 621, 188
    h, V, w, dt = 1.68, 8.0, 0.15, 0.1

    def pose(t):
        psi = w * t
        R = np.array([[np.cos(psi), 0, np.sin(psi)], [0, 1, 0], [-np.sin(psi), 0, np.cos(psi)]])
        return R, np.array([V / w * (1 - np.cos(psi)), 0.0, V / w * np.sin(psi)])

    def proj(P, t):
        R, c = pose(t)
        Pc = (P - c) @ R
        return np.stack([f * Pc[:, 0] / Pc[:, 2] + cu, f * Pc[:, 1] / Pc[:, 2] + cv], axis=1), Pc[:, 2]

    def visible(P):
        for t in (-dt, 0.0, dt):
            x, z = proj(P[None], t)
            if not (z[0] > 0 and 0 <= x[0, 0] <= W - 1 and 0 <= x[0, 1] <= H - 1):
                return False
        return True

    rng = np.random.default_rng(seed)
    G, Wl = [], []
    while len(G) < 400:
        z = rng.uniform(5, zmax)
        P = np.array([rng.uniform(-z * cu / f, z * (W - cu) / f), h, z])
        if visible(P):
            G.append(P)
    while len(Wl) < 300:
        z = rng.uniform(5, zmax)
        P = np.array([rng.choice([-1, 1]) * wall_x, rng.uniform(h - 3.0, h), z])
        if visible(P):
            Wl.append(P)
    P = np.array(G + Wl)
    xs = np.stack([proj(P, t)[0] for t in (-dt, 0.0, dt)])
    return dict(xy=xs, ground=np.r_[np.ones(400, bool), np.zeros(300, bool)], Z=proj(P, 0.0)[1],
                f=f, cu=cu, cv=cv, h=h, V=V, w=w, dt=dt)
