"""`antarium layout`: the dome's LED layout — summary figures, pictures, per-LED table, regeneration."""

from __future__ import annotations

import argparse
import math
import time

HELP = "print the LED layout summary, draw it, export the per-LED table, or regenerate the layout"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default=None, metavar="FOLDER",
                        help="folder for the pictures layout_mollweide.png and layout_3d.png, made if missing, "
                             "existing pictures overwritten (default: the current folder, and none with --export or "
                             "--regenerate unless --out is given)")
    parser.add_argument("--no-pictures", action="store_true", help="print the summary only")
    parser.add_argument("--export", metavar="FILE",
                        help="write the full per-LED table (.csv or .json, in an existing folder; an existing file is "
                             "overwritten)")
    parser.add_argument("--regenerate", action="store_true",
                        help="rerun the seeded layout search (about 2 s) and write it to --layout-out")
    parser.add_argument("--layout-out", metavar="FILE.npz",
                        help="where --regenerate writes (needed with it; an existing file is overwritten, the shipped "
                             "geometry/data/layout.npz only when named)")
    parser.add_argument("--margin-mm", type=float, default=None,
                        help="LED centre to board edge, mm (with --regenerate; default: the search's own)")
    parser.add_argument("--min-pitch-mm", type=float, default=None,
                        help="minimum GB pitch, mm (with --regenerate; default: the search's own)")


def _metres(value_mm: float, option: str) -> float:
    """A length option given in mm, in metres; ValueError naming the option and the value as given (mm) outside
    (0, `MAX_LENGTH`)."""
    from antarium.geometry.layout import MAX_LENGTH

    high_mm = MAX_LENGTH * 1e3
    if not (math.isfinite(value_mm) and 0 < value_mm < high_mm):
        raise ValueError(f"{option} must be in (0, {high_mm:g}) mm, got {value_mm:g} mm")
    return value_mm / 1e3


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
    from antarium.commands import check_output
    from antarium.geometry import LayoutParams, generate_layout, load_dome
    from antarium.geometry.layout import SHIPPED_LAYOUT, save_layout
    from antarium.geometry.spacing import layout_summary

    # every output checked before the work: the search, the summary and the pictures are not thrown away
    # an empty name is bad input, not "not given"; the writers get the names as checked (`~` expanded)
    if args.export is not None:
        export_path = check_output(args.export, "--export", suffixes=(".csv", ".json"), make_folders=False)
    if args.layout_out is not None and not args.regenerate:
        raise ValueError("--layout-out applies only with --regenerate")
    if args.regenerate:
        kw = {}
        if args.margin_mm is not None:
            kw["margin"] = _metres(args.margin_mm, "--margin-mm")
        if args.min_pitch_mm is not None:
            kw["gb_min_pitch"] = _metres(args.min_pitch_mm, "--min-pitch-mm")
        if args.layout_out is None:
            raise ValueError("--regenerate needs --layout-out FILE.npz (to replace the shipped layout, name it: "
                             f"--layout-out {SHIPPED_LAYOUT})")
        layout_path = check_output(args.layout_out, "--layout-out", suffixes=(".npz",))
    elif args.margin_mm is not None or args.min_pitch_mm is not None:
        raise ValueError("--margin-mm and --min-pitch-mm apply only with --regenerate")
    if args.no_pictures and args.out is not None:
        raise ValueError("--out names the pictures' folder and --no-pictures draws none: give one of them")
    pictures = not args.no_pictures and (args.out is not None or not (args.export is not None or args.regenerate))
    if pictures:
        out = check_output("." if args.out is None else args.out, "--out", folder=True)
    if args.regenerate:
        layout = generate_layout(LayoutParams(**kw), progress=True)
        layout_path.parent.mkdir(parents=True, exist_ok=True)
        save_layout(layout, layout_path)
        print(f"layout written to {layout_path}")
    else:
        layout_path = None
    t0 = time.perf_counter()
    dome = load_dome(layout_path)
    dome.directions, dome.gain  # noqa: B018 - measure the full build
    load_ms = (time.perf_counter() - t0) * 1e3
    print_summary(layout_summary(dome))
    print(f"  layout load time {load_ms:.1f} ms")
    if args.export is not None:
        from antarium.geometry.table import export_table

        print(f"per-LED table: {export_table(dome, export_path)}")
    if pictures:
        from antarium.plots.layout import dome_3d, mollweide_map

        out.mkdir(parents=True, exist_ok=True)
        print(f"picture: {mollweide_map(dome, out / 'layout_mollweide.png')}")
        print(f"picture: {dome_3d(dome, out / 'layout_3d.png')}")
    return 0
