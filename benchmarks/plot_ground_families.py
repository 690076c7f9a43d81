"""README picture of every rover ground appearance family (issue 13, item 1).

One row per family of ``polar_sim.sim.builders.rover_appearance.FAMILIES`` and one for the default look: the
front camera of ``rover_flat`` (seed 10,003), KITTI-like (1242x376 rendered, reduced 2x to 621x188
as the routes are recorded), after the same 2 s drive from the start. Left: the family with its
default options (``{"ground": {"family": f}}``, a plain gradient sky and the default sun). Right: a
seeded draw ``appearance=f`` (each zone its own colours; a random sky and light). Each row is labelled
with the family name and whether the ground experiments tuned on it (dev) or only ever score it (test).

Usage: python benchmarks/plot_ground_families.py [--out docs/images/rover_ground_families.png]
"""

import argparse
import os

os.environ.setdefault("MUJOCO_GL", "egl")

import cv2  # noqa: E402

SCENE, SEED, STEPS, ACTION = "rover_flat", 10_003, 20, (6.0, 0.0)


def frame(look):
    """The 621x188 front-camera image of the scene under ``look`` after the short drive."""
    from polar_sim.sim import World
    from polar_sim.sim.recorders.rover_sequences import KITTI_FOVY_DEG

    with World(SCENE, seed=SEED, camera_fovy=KITTI_FOVY_DEG, appearance=look) as w:
        for _ in range(STEPS):
            w.step(ACTION)
        return cv2.pyrDown(w.camera("front", width=1242, height=376).rgb)


def main(out):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from polar_sim.sim.builders.rover_appearance import FAMILIES
    from polar_sim.sim.recorders.rover_sequences import DEV_FAMILIES, DEV_ONLY_FAMILIES, TEST_ONLY_FAMILIES

    rows = [("default look (appearance=None)", "asphalt / gravel / grass / dirt zones; dev (issue-5 routes)", None, None)]
    for f, (desc, _, _) in FAMILIES.items():
        split = ("dev only: the dev split's periodic ground" if f in DEV_ONLY_FAMILIES else "dev: tuned on"
                 if f in DEV_FAMILIES else "test only: never tuned on" if f in TEST_ONLY_FAMILIES else "?")
        rows.append((f, f"{desc}; {split}", {"ground": {"family": f}, "sky": {"kind": "gradient"}}, f))
    fig, axes = plt.subplots(len(rows), 2, figsize=(12.4, 2.05 * len(rows)), squeeze=False)
    for (name, desc, spec, fam), (a, b) in zip(rows, axes):
        a.imshow(frame(spec))
        if fam is None:
            b.axis("off")
            b.text(0.02, 0.5, "the scene as it always was:\nno appearance option", fontsize=9, va="center")
        else:
            b.imshow(frame(fam))
        a.set_title(f"{name}: family defaults" if fam else name, fontsize=9, loc="left", fontweight="bold")
        if fam:
            b.set_title(f'{name}: seeded draw, appearance="{fam}"', fontsize=9, loc="left", fontweight="bold")
        a.set_xlabel(desc, fontsize=7.5, loc="left")
        for ax in (a, b):
            ax.set_xticks([])
            ax.set_yticks([])
    fig.suptitle(f"Rover ground appearance families: {SCENE} (seed {SEED}), front camera 621x188, simulated",
                 fontsize=11, fontweight="bold")
    fig.tight_layout(rect=(0, 0, 1, 0.985))
    os.makedirs(os.path.dirname(out) or ".", exist_ok=True)
    fig.savefig(out, dpi=80)
    plt.close(fig)
    print(out)


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="docs/images/rover_ground_families.png")
    main(ap.parse_args().out)
