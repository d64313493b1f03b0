"""`antarium layout`: the dome's LED layout — summary figures, pictures, per-LED table, regeneration."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

HELP = "print the LED layout summary, draw it, export the per-LED table, or regenerate the layout"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default=None,
                        help="folder for the pictures (default: the current folder, and none with --export or "
                             "--regenerate unless --out is given)")
    parser.add_argument("--no-pictures", action="store_true", help="print the summary only")
    parser.add_argument("--export", metavar="FILE", help="write the full per-LED table (.csv or .json)")
    parser.add_argument("--regenerate", action="store_true",
                        help="rerun the seeded layout search and write it to --layout-out")
    parser.add_argument("--layout-out", metavar="FILE", help="where --regenerate writes (default: the shipped file)")
    parser.add_argument("--margin-mm", type=float, default=None,
                        help="LED centre to board edge, mm (with --regenerate)")
    parser.add_argument("--min-pitch-mm", type=float, default=None, help="minimum GB pitch, mm (with --regenerate)")


def print_summary(summary: dict) -> None:
    s = summary
    print(f"Antarium dome: {s['panels']} panels, {s['gb_pixels']:,} GB pixels, {s['uv_pixels']} UV pixels")
    print(f"  solid: circumradius {s['circumradius_m']:.4f} m, inradius {s['inradius_m']:.4f} m, "
          f"triangle base {s['triangle_base_m'] * 1e3:.1f} mm, legs {s['triangle_leg_m'] * 1e3:.1f} mm")
    print(f"  elevation coverage {s['elevation_min_deg']:.1f} deg .. {s['elevation_max_deg']:.1f} deg; "
          f"LED distance {s['distance_min_m']:.3f}..{s['distance_max_m']:.3f} m; gain {s['gain_min']:.3f}..1")
    print(f"  lattice pitch: GB {s['gb_pitch_mm']:.2f} mm, UV {s['uv_pitch_mm']:.2f} mm")
    print("  nearest-neighbour angle (deg)      n     mean  median    min     max     CV")
    for kind in ("gb", "uv"):
        for part in ("all", "within", "seam"):
            v = s[f"{kind}_spacing"][part]
            print(f"    {kind.upper():2s} {part:7s} {'':15s} {v['n']:6d}  {v['mean_deg']:6.3f}  {v['median_deg']:6.3f}"
                  f"  {v['min_deg']:6.3f}  {v['max_deg']:6.3f}  {v['cv']:.3f}")


def run(args: argparse.Namespace) -> int:
    from antarium.geometry import LayoutParams, generate_layout, load_dome
    from antarium.geometry.layout import SHIPPED_LAYOUT, save_layout
    from antarium.geometry.spacing import layout_summary

    if args.export:
        export = Path(args.export)
        if export.suffix.lower() not in (".csv", ".json"):
            raise ValueError(f"--export file must end in .csv or .json, got {export.name!r}")
        if not export.parent.is_dir():
            raise ValueError(f"--export: folder {str(export.parent)!r} does not exist")
    layout_path = None
    if args.regenerate:
        kw = {}
        if args.margin_mm is not None:
            kw["margin"] = args.margin_mm / 1e3
        if args.min_pitch_mm is not None:
            kw["gb_min_pitch"] = args.min_pitch_mm / 1e3
        layout = generate_layout(LayoutParams(**kw), progress=True)
        layout_path = Path(args.layout_out or SHIPPED_LAYOUT)
        save_layout(layout, layout_path)
        print(f"layout written to {layout_path}")
    elif args.margin_mm is not None or args.min_pitch_mm is not None:
        raise ValueError("--margin-mm and --min-pitch-mm apply only with --regenerate")
    t0 = time.perf_counter()
    dome = load_dome(layout_path)
    dome.directions, dome.gain  # noqa: B018 - measure the full build
    load_ms = (time.perf_counter() - t0) * 1e3
    print_summary(layout_summary(dome))
    print(f"  layout load time {load_ms:.1f} ms")
    if args.export:
        from antarium.geometry.table import export_table

        print(f"per-LED table: {export_table(dome, args.export)}")
    if not args.no_pictures and (args.out is not None or not (args.export or args.regenerate)):
        from antarium.plots.layout import dome_3d, mollweide_map

        out = Path(args.out or ".")
        out.mkdir(parents=True, exist_ok=True)
        print(f"picture: {mollweide_map(dome, out / 'layout_mollweide.png')}")
        print(f"picture: {dome_3d(dome, out / 'layout_3d.png')}")
    return 0
