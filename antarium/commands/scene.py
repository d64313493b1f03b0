"""`antarium scene habitat --out habitat.glb`: write the default habitat as a GLB (+ its panorama PNG)."""

from __future__ import annotations

import argparse

HELP = "write the procedural default habitat as a GLB file that opens in any 3D viewer (plus its panorama)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("name", choices=["habitat"], help="the scene to write")
    parser.add_argument("--out", default="habitat.glb", metavar="FILE.glb",
                        help="GLB file to write, its panorama next to it as NAME_panorama.png (default %(default)s; "
                             "folders made, existing files are overwritten)")
    parser.add_argument("--seed", type=int, default=0,
                        help="random seed of the habitat (an integer >= 0; default %(default)s)")


def run(args: argparse.Namespace) -> int:

    import numpy as np

    from antarium.commands import check_output
    from antarium.core.numbers import check_number
    from antarium.renderers.habitat import habitat_objects, panorama_image
    from antarium.renderers.meshes import save_glb

    seed = check_number("--seed", args.seed, 0, integer=True)
    out = check_output(args.out, "--out", suffixes=(".glb",))  # both files checked before either is written
    pano = check_output(out.with_name(out.stem + "_panorama.png"), "--out (its panorama)", suffixes=(".png",))
    out.parent.mkdir(parents=True, exist_ok=True)
    objects = habitat_objects(seed=seed)
    save_glb(objects, out)
    rgba = (np.clip(panorama_image(seed), 0, 1) * 255 + 0.5).astype(np.uint8)
    import cv2

    if not cv2.imwrite(str(pano), rgba[:, :, [2, 1, 0, 3]]):
        raise ValueError(f"cannot write {pano}")
    n = sum(o.mesh.n_triangles for o in objects.values())
    print(f"habitat (seed {seed}): {len(objects)} objects, {n} triangles -> {out}; panorama -> {pano}")
    print(f"render it with: antarium render '{{\"scene\": \"{out}\", \"panorama\": \"{pano}\"}}'")
    return 0
