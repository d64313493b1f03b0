"""The full per-LED table: export to CSV or JSON and read back (round trip exact to the printed precision)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from . import addressing

#: column -> (dtype, unit/meaning); positions in metres, angles in degrees at this edge.
COLUMNS: dict[str, tuple[str, str]] = {
    "index": ("int", "global pixel index, panel * 370 + local"),
    "panel": ("int", "0..54"),
    "pentagon": ("int", "0..10"),
    "slot": ("int", "0..4 within the pentagon"),
    "local": ("int", "0..369, order in the panel datagram"),
    "kind": ("str", "GB or UV"),
    "actuator": ("int", "polariser actuator 0..8 of a UV pixel, -1 for GB"),
    "x_m": ("float", "position, m"),
    "y_m": ("float", "position, m"),
    "z_m": ("float", "position, m"),
    "azimuth_deg": ("float", "deg in (-180, 180], 0 along +x, counter-clockwise from above"),
    "elevation_deg": ("float", "deg above the horizon"),
    "distance_m": ("float", "m from the dome centre"),
    "emission_angle_deg": ("float", "deg between LED axis and the ray to the centre"),
    "gain": ("float", "photometric gain (0, 1]"),
    "led0_chain": ("int", "driver chain 0..3 of LED 0 (green / plain UV)"),
    "led0_chip": ("int", "chip in chain"),
    "led0_channel": ("int", "channel 0..15"),
    "led1_chain": ("int", "driver chain 0..3 of LED 1 (blue / polarised UV)"),
    "led1_chip": ("int", "chip in chain"),
    "led1_channel": ("int", "channel 0..15"),
}


def led_table(dome) -> dict[str, np.ndarray]:
    """Column name -> (20350,) array, in global pixel order."""
    local = dome.local
    drivers = [addressing.led_to_driver(local, np.full_like(local, led)) for led in (0, 1)]
    return {
        "index": dome.index,
        "panel": dome.panel,
        "pentagon": dome.pentagon,
        "slot": dome.slot,
        "local": local,
        "kind": np.where(dome.is_uv, "UV", "GB"),
        "actuator": np.where(dome.is_uv, local - addressing.GB_PER_PANEL, -1),
        "x_m": dome.positions[:, 0],
        "y_m": dome.positions[:, 1],
        "z_m": dome.positions[:, 2],
        "azimuth_deg": np.degrees(dome.azimuth),
        "elevation_deg": np.degrees(dome.elevation),
        "distance_m": dome.distance,
        "emission_angle_deg": np.degrees(dome.emission_angle),
        "gain": dome.gain,
        **{
            f"led{led}_{part}": drivers[led][i]
            for led in (0, 1)
            for i, part in enumerate(("chain", "chip", "channel"))
        },
    }


def export_table(dome, path: str | Path) -> Path:
    """Write the table as .csv or .json (by suffix); floats with 17 significant digits (exact round trip)."""
    path = Path(path)
    table = led_table(dome)
    if path.suffix.lower() == ".csv":
        with path.open("w", newline="") as f:
            w = csv.writer(f)
            w.writerow(COLUMNS)
            cols = [table[c].tolist() for c in COLUMNS]
            w.writerows(zip(*[[repr(v) if isinstance(v, float) else v for v in col] for col in cols], strict=True))
    elif path.suffix.lower() == ".json":
        doc = {
            "columns": {c: {"type": t, "meaning": m} for c, (t, m) in COLUMNS.items()},
            "rows": len(table["index"]),
            "data": {c: table[c].tolist() for c in COLUMNS},
        }
        path.write_text(json.dumps(doc))
    else:
        raise ValueError(f"export file must end in .csv or .json, got {path.name!r}")
    return path


def read_table(path: str | Path) -> dict[str, np.ndarray]:
    """Read a table written by `export_table` back into column arrays (ValueError naming the file for a table
    without rows, a CSV row of the wrong length or a JSON table without all of `COLUMNS`)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"LED table not found: {path}")
    if path.suffix.lower() == ".csv":
        with path.open(newline="") as f:
            rows = list(csv.reader(f))
        if len(rows) < 2:
            raise ValueError(f"{path}: no rows; an LED table has a header and one row per pixel")
        header, body = rows[0], rows[1:]
        if header != list(COLUMNS):
            raise ValueError(f"{path}: columns {header} do not match the LED table columns {list(COLUMNS)}")
        for line, row in enumerate(body, start=2):
            if len(row) != len(header):
                raise ValueError(f"{path}: row {line} has {len(row)} fields; allowed {len(header)}")
        raw = dict(zip(header, zip(*body, strict=True), strict=True))
    elif path.suffix.lower() == ".json":
        raw = json.loads(path.read_text())["data"]
        missing = [c for c in COLUMNS if c not in raw]
        if missing:
            raise ValueError(f"{path}: the table lacks the columns {missing}")
    else:
        raise ValueError(f"LED table must end in .csv or .json, got {path.name!r}")
    conv = {"int": np.int64, "float": np.float64, "str": str}
    return {c: np.asarray(raw[c]).astype(conv[t]) for c, (t, _) in COLUMNS.items()}
