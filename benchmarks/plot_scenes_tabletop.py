"""Pictures of the manipulation scenes, and the statistics of the tracking sequences.

    python benchmarks/plot_scenes_tabletop.py            # docs/img/scene_tabletop.png, scene_object_orbit.png,
                                                         # tabletop_appearance.png (every appearance family)
    python benchmarks/plot_scenes_tabletop.py --stats    # also a table of every sequence (occlusion, contact, speed)

Each picture is the ``rgbd`` camera's RGB, depth and labels (plus, for tabletop, a frame of the
hand holding the target and its amodal mask), rendered at 640x480 and tiled at half size.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import cv2  # noqa: E402
import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def _label(img, text):
    img = img.copy()
    cv2.putText(img, text, (10, 34), cv2.FONT_HERSHEY_SIMPLEX, 1.0, (0, 0, 0), 5, cv2.LINE_AA)
    cv2.putText(img, text, (10, 34), cv2.FONT_HERSHEY_SIMPLEX, 1.0, (255, 255, 255), 2, cv2.LINE_AA)
    return img


def _sheet(tiles, cols=2):
    small = [cv2.resize(t, (t.shape[1] // 2, t.shape[0] // 2), interpolation=cv2.INTER_AREA) for t in tiles]
    while len(small) % cols:
        small.append(np.zeros_like(small[0]))
    return np.vstack([np.hstack(small[i : i + cols]) for i in range(0, len(small), cols)])


def scene_pictures(out_dir):
    from polar_sim.sim import World
    from polar_sim.sim.pictures import colourise_depth, colourise_labels, save_png

    out_dir = Path(out_dir)
    paths = []
    # tabletop: the first frame, and the hand holding the target during "lift"
    w = World("tabletop", seed=0, script="lift", target="mug")
    f = w.camera("rgbd")
    tiles = [_label(f.rgb, "tabletop rgbd: rgb (t = 0)"), _label(colourise_depth(f.depth), "depth"),
             _label(colourise_labels(f.labels), "labels")]
    while w.truth()["phase"] != "tilt":
        w.step()
    for _ in range(20):
        w.step()
    f = w.camera("rgbd")
    full = w.amodal_mask("rgbd")
    tr = w.truth()
    occ = 1 - (f.labels == 3).sum() / max(full.sum(), 1)
    tiles.append(_label(f.rgb, f"t = {tr['time']:.1f} s, {tr['phase']}, occlusion {occ:.0%}"))
    lab = colourise_labels(f.labels)
    edge = cv2.morphologyEx(full.astype(np.uint8), cv2.MORPH_GRADIENT, np.ones((3, 3), np.uint8)) > 0
    lab[edge] = (0, 255, 255)
    tiles.append(_label(lab, "labels + amodal outline (cyan)"))
    tiles.append(_label(w.render_view(lookat=(0.0, 0.0, 0.85), distance=1.6, azimuth=60, elevation=-30),
                        "overview"))
    w.close()
    paths.append(save_png(out_dir / "scene_tabletop.png", _sheet(tiles, 3)))

    w = World("object_orbit", seed=0, object="drill", radius=0.6)
    tiles = []
    for k in range(3):
        f = w.camera("rgbd")
        tiles.append(_label(f.rgb, f"object_orbit rgbd, t = {w.time:.1f} s"))
        if k == 0:
            tiles.append(_label(colourise_depth(f.depth), "depth"))
            tiles.append(_label(colourise_labels(f.labels), "labels"))
        for _ in range(60):
            w.step()
    tiles.append(_label(w.render_view(lookat=(0.0, 0.0, 0.5), distance=2.2, azimuth=45, elevation=-25), "overview"))
    w.close()
    paths.append(save_png(out_dir / "scene_object_orbit.png", _sheet(tiles, 3)))
    return paths


#: The scenes of the appearance picture: (seed, script, target, frames stepped).
APPEARANCE_SCENES = ((5, "touch", "blocks", 75), (1, "lift", "mug", 150), (2, "touch", "bottle", 75))


def appearance_pictures(out_dir):
    """docs/img/tabletop_appearance.png: each appearance family (rows) on three scenes (columns)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from polar_sim.sim import World
    from polar_sim.sim.builders.tabletop_appearance import DEV_FAMILIES, TEST_FAMILIES

    fams = list(DEV_FAMILIES) + list(TEST_FAMILIES) + ["random"]
    fig, axes = plt.subplots(len(fams), len(APPEARANCE_SCENES), figsize=(4.2 * len(APPEARANCE_SCENES), 3.3 * len(fams)))
    for i, fam in enumerate(fams):
        for j, (seed, script, target, n) in enumerate(APPEARANCE_SCENES):
            w = World("tabletop", seed=seed, script=script, target=target, appearance=fam)
            for _ in range(n):
                w.step()
            f = w.camera("rgbd", width=480, height=360)
            a = w.meta.appearance
            w.close()
            ax = axes[i, j]
            ax.imshow(f.rgb)
            ax.set_xticks([]), ax.set_yticks([])
            split = "dev" if fam in DEV_FAMILIES else "test" if fam in TEST_FAMILIES else "test (random)"
            ax.set_title(f"{fam} [{split}]: {target}, {script}, seed {seed}\nobjects {a['objects']}, hand {a['hand']}, "
                         f"table {a['table']}, key light x{a['light']['intensity']:.2f} at {a['light']['azimuth_deg']:+.0f} deg",
                         fontsize=7)
    fig.suptitle("tabletop appearance families (simulated RGB, 480x360): rows are families, columns scenes; "
                 "[dev] families were used while tuning, [test] never", fontsize=10)
    fig.tight_layout(rect=(0, 0, 1, 0.985))
    path = Path(out_dir) / "tabletop_appearance.png"
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def sequence_stats(width=320, height=240, only=None, split="dev"):
    """Per sequence of a split: occlusion range, frames in contact / held, peak speeds, displacement."""
    from polar_sim.sim.recorders.tabletop_sequences import SPLIT_SEEDS, list_sequences, sequence_spec, sequence_world
    from polar_sim.sim.truth import LABELS

    rows = []
    for name in list_sequences(split):
        spec = sequence_spec(name)
        if only and name not in only:
            continue
        t0 = time.time()
        w = sequence_world(name, SPLIT_SEEDS[split][0])
        tgt = w.meta.target
        occ, contact, held, v, om, phases = [], 0, 0, [], [], []
        p0 = w.truth()["objects"][tgt][:3, 3]
        for k in range(spec.frames):
            if k:
                w.step()
            f = w.camera("rgbd", width=width, height=height)
            full = w.amodal_mask("rgbd", width=width, height=height)
            tr = w.truth()
            if full.any():
                occ.append(1 - (f.labels == LABELS["target"]).sum() / full.sum())
            contact += bool(tr["in_contact"])
            held += bool(tr["grasped"])
            tw = tr["object_twists"][tgt]
            v.append(np.linalg.norm(tw[:3]))
            om.append(np.degrees(np.linalg.norm(tw[3:])))
            if not phases or phases[-1] != tr["phase"]:
                phases.append(tr["phase"])
        p1 = w.truth()["objects"][tgt][:3, 3]
        w.close()
        occ = np.array(occ)
        rows.append((name, tgt, spec.frames, float(occ.min()), float(np.percentile(occ, 50)), float(occ.max()),
                     contact, held, max(v), max(om), float(np.linalg.norm(p1 - p0)), phases[-1]))
        print(f"{name:14s} {tgt:8s} {spec.frames:4d} occl {occ.min():.2f}-{occ.max():.2f} (median {np.median(occ):.2f}) "
              f"contact {contact:3d} held {held:3d} v {max(v):.2f} m/s w {max(om):4.0f} deg/s "
              f"moved {np.linalg.norm(p1 - p0) * 100:.1f} cm, ends in {phases[-1]!r} ({time.time() - t0:.0f} s)",
              flush=True)
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "docs" / "img"))
    ap.add_argument("--stats", action="store_true", help="also print the sequence statistics table")
    ap.add_argument("--no-pictures", action="store_true")
    ap.add_argument("--only", nargs="*", help="sequences for --stats (default: all)")
    ap.add_argument("--split", default="dev", help="sequences for --stats: dev, dev_appearance or test")
    a = ap.parse_args(argv)
    if not a.no_pictures:
        for p in scene_pictures(a.out) + [appearance_pictures(a.out)]:
            print("wrote", p)
    if a.stats:
        rows = sequence_stats(only=a.only, split=a.split)
        print("\n| sequence | object | frames | occlusion min-max (median) | contact frames | held frames |"
              " peak speed | peak rotation | net displacement |")
        print("|---|---|---|---|---|---|---|---|---|")
        for n, o, fr, lo, med, hi, c, h, v, om, d, _ in rows:
            print(f"| {n} | {o} | {fr} | {lo:.0%}-{hi:.0%} ({med:.0%}) | {c} | {h} | {v:.2f} m/s | {om:.0f} deg/s |"
                  f" {d * 100:.1f} cm |")


if __name__ == "__main__":
    sys.exit(main())
