"""`antarium scene habitat --out habitat.glb`: write the default habitat as a GLB (+ its panorama PNG)."""

from __future__ import annotations

import argparse

HELP = "write the procedural default habitat as a GLB file that opens in any 3D viewer (plus its panorama)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("name", choices=["habitat"], help="the scene to write")
    parser.add_argument("--out", default="habitat.glb", help="GLB file to write (default habitat.glb)")
    parser.add_argument("--seed", type=int, default=0, help="random seed of the habitat (default 0)")


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    import numpy as np

    from antarium.renderers.habitat import habitat_objects, panorama_image
    from antarium.renderers.meshes import save_glb

    out = Path(args.out)
    if out.suffix.lower() != ".glb":
        raise ValueError(f"--out must end in .glb, got {out}")
    objects = habitat_objects(seed=args.seed)
    save_glb(objects, out)
    pano = out.with_name(out.stem + "_panorama.png")
    rgba = (np.clip(panorama_image(args.seed), 0, 1) * 255 + 0.5).astype(np.uint8)
    import cv2

    if not cv2.imwrite(str(pano), rgba[:, :, [2, 1, 0, 3]]):
        raise ValueError(f"cannot write {pano}")
    n = sum(o.mesh.n_triangles for o in objects.values())
    print(f"habitat (seed {args.seed}): {len(objects)} objects, {n} triangles -> {out}; panorama -> {pano}")
    print(f"render it with: antarium render '{{\"scene\": \"{out}\", \"panorama\": \"{pano}\"}}'")
    return 0
