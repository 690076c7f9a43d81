"""Figure for the README: GPISMap2D over all gazebo1 scans (SDF heat map, zero level, path).

Usage: python benchmarks/plot_gpis_gazebo1.py [--out docs/img/gpis_gazebo1.png] [--scans N]
"""

from __future__ import annotations

import argparse

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from tqdm import tqdm  # noqa: E402

from polar_sim.datasets import load_gazebo1  # noqa: E402
from polar_sim.gpis import GPISMap2D  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="docs/img/gpis_gazebo1.png")
    ap.add_argument("--scans", type=int, default=None, help="use the first N scans (default all)")
    ap.add_argument("--res", type=float, default=0.05, help="grid step, m")
    a = ap.parse_args(argv)
    g = load_gazebo1()
    n = len(g["ranges"]) if a.scans is None else a.scans
    m = GPISMap2D(sensor_offset=g["sensor_offset"])   # the log gives base poses
    for k in tqdm(range(n), desc="gazebo1 scans"):
        m.update(g["thetas"], g["ranges"][k], g["poses"][k])
    s = m.samples()["points"]
    lo, hi = s.min(0) - 1.0, s.max(0) + 1.0
    xs, ys = np.arange(lo[0], hi[0], a.res), np.arange(lo[1], hi[1], a.res)
    X, Y = np.meshgrid(xs, ys, indexing="xy")
    d, _, v = m.query(np.stack([X.ravel(), Y.ravel()], 1))
    D = d.reshape(X.shape)
    fig, ax = plt.subplots(figsize=(9, 7.5), dpi=120)
    im = ax.imshow(np.clip(D, -1.0, 3.0), origin="lower", extent=(xs[0], xs[-1], ys[0], ys[-1]),
                   cmap="RdBu", vmin=-3.0, vmax=3.0)
    for ln in m.surface():
        ax.plot(ln[:, 0], ln[:, 1], "k-", lw=0.8)
    p = g["poses"][:n]
    ax.plot(p[:, 0], p[:, 1], "-", color="orange", lw=1.2, label="robot path")
    ax.plot(p[0, 0], p[0, 1], "o", color="orange")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"GPISMap2D (default mode) after {n} gazebo1 scans: signed distance [m]")
    fig.colorbar(im, ax=ax, shrink=0.8, label="signed distance [m] (clipped to [-1, 3])")
    ax.legend(loc="lower right")
    fig.tight_layout()
    fig.savefig(a.out)
    print(f"wrote {a.out}: {len(s)} samples, map {m.nbytes() / 1e6:.1f} MB")


if __name__ == "__main__":
    main()
