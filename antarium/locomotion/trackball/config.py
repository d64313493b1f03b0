"""The `[trackball]` section of the rig config: device ids, sensor placement, counts per mm and signs.

    [trackball]
    vendor_id = 0x1209          # USB ids of the trackball (pid.codes test ids by default)
    product_id = 0x0001
    ball_radius = 0.05          # metres
    sample_rate_hz = 1000       # reports per second asked of the device (1..1000)
    resolution_cpi = 1200       # sensor resolution asked of the device (counts per inch, 100..12000)
    slip_floor_mm = 0.1         # see `BallSolver`: keeps the slip ratio finite when the ball is still

    [[trackball.sensors]]       # one table per sensor, in the order of the device's report
    azimuth_deg = 0.0
    elevation_deg = 0.0
    roll_deg = 0.0
    counts_per_mm = [47.24, 47.24]   # sensor x, sensor y (written by `antarium trackball calibrate`);
                                     # left out: resolution_cpi / 25.4 (the sensor's nominal value)
    signs = [1, 1]                   # +1 or -1 per sensor axis (mounting)
    calibration_cpi = 1200           # the resolution counts_per_mm were calibrated at (written by calibrate)

A missing key takes its default (`ball_radius`: in a rig file, its `[loop] ball_radius_m` if it sets one); an
unknown key or a bad value raises `TrackballConfigError` naming it. `write_section` writes a calibration's result
into a rig file: only the `counts_per_mm`, `signs` and `calibration_cpi` of its `[[trackball.sensors]]`, every
other byte (comments included) kept; a file it cannot edit that way is rewritten whole after a copy to `<file>.bak`.
"""

from __future__ import annotations

import math
import os
import re
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from antarium.config import trackball_table
from antarium.core.ball import BALL_RADIUS_M
from antarium.locomotion.trackball.kinematics import BallSolver, SensorPlacement
from antarium.locomotion.trackball.protocol import N_SENSORS

DEFAULT_CPI = 1200


def nominal_counts_per_mm(resolution_cpi: float) -> float:
    """Counts per mm of a sensor at `resolution_cpi` counts per inch, before calibration (the one place)."""
    return resolution_cpi / 25.4


class TrackballConfigError(ValueError):
    """A `[trackball]` section that cannot be used; the message names the key and what is allowed."""


@dataclass(frozen=True)
class SensorConfig:
    """One sensor: placement (degrees at this edge), calibration of its x and y counts.

    counts_per_mm None: the nominal value of the config's `resolution_cpi` (`TrackballConfig` fills it in).
    calibration_cpi: the resolution `counts_per_mm` were calibrated at (None: not recorded); a config whose
    `resolution_cpi` differs is refused.
    """

    azimuth_deg: float
    elevation_deg: float = 0.0
    roll_deg: float = 0.0
    counts_per_mm: tuple[float, float] | None = None
    signs: tuple[int, int] = (1, 1)
    calibration_cpi: int | None = None

    def placement(self) -> SensorPlacement:
        return SensorPlacement(
            math.radians(self.azimuth_deg), math.radians(self.elevation_deg), math.radians(self.roll_deg)
        )


@dataclass(frozen=True)
class TrackballConfig:
    vendor_id: int = 0x1209
    product_id: int = 0x0001
    ball_radius: float = BALL_RADIUS_M
    sample_rate_hz: int = 1000
    resolution_cpi: int = DEFAULT_CPI
    slip_floor_mm: float = 0.1
    sensors: tuple[SensorConfig, ...] = field(
        default_factory=lambda: (SensorConfig(0.0), SensorConfig(90.0))
    )

    def __post_init__(self) -> None:
        nominal = nominal_counts_per_mm(self.resolution_cpi)
        sensors = tuple(replace(s, counts_per_mm=(nominal, nominal)) if s.counts_per_mm is None else s
                        for s in self.sensors)
        object.__setattr__(self, "sensors", sensors)
        for i, s in enumerate(sensors):
            if s.calibration_cpi is not None and s.calibration_cpi != self.resolution_cpi:
                raise TrackballConfigError(
                    f"[[trackball.sensors]] #{i} counts_per_mm were calibrated at calibration_cpi = "
                    f"{s.calibration_cpi} but [trackball] resolution_cpi = {self.resolution_cpi}: set resolution_cpi "
                    f"= {s.calibration_cpi} or calibrate again (antarium trackball calibrate)")

    def solver(self) -> BallSolver:
        return BallSolver(tuple(s.placement() for s in self.sensors), self.ball_radius, self.slip_floor_mm * 1e-3)

    def metres_per_count(self, applied_cpi: int | None = None) -> list[float]:
        """Signed metres per count of each sensor axis, in report order (x0, y0, x1, y1).

        applied_cpi: the resolution the device says it applied (GET_INFO; the sensor rounds to its own step):
        a sensor left at the nominal counts per mm of `resolution_cpi` takes the applied one's instead (a
        calibrated sensor keeps its own: the calibration measured the applied resolution)."""
        asked = nominal_counts_per_mm(self.resolution_cpi)
        out = []
        for s in self.sensors:
            cpmm = s.counts_per_mm
            if applied_cpi is not None and s.calibration_cpi is None and cpmm == (asked, asked):
                cpmm = (nominal_counts_per_mm(applied_cpi),) * 2
            out += [sign * 1e-3 / c for c, sign in zip(cpmm, s.signs, strict=True)]
        return out


_TOP_KEYS = {
    "vendor_id": (int, 0, 0xFFFF),
    "product_id": (int, 0, 0xFFFF),
    "ball_radius": (float, 1e-3, 1.0),
    "sample_rate_hz": (int, 1, 1000),
    "resolution_cpi": (int, 100, 12000),
    "slip_floor_mm": (float, 1e-6, 100.0),
}
_SENSOR_KEYS = {"azimuth_deg", "elevation_deg", "roll_deg", "counts_per_mm", "signs", "calibration_cpi"}


def _number(where: str, value: Any, kind: type, lo: float, hi: float) -> Any:
    ok_type = (int,) if kind is int else (int, float)
    if isinstance(value, bool) or not isinstance(value, ok_type) or not math.isfinite(value):
        raise TrackballConfigError(f"{where} must be {'an integer' if kind is int else 'a finite number'}, "
                                   f"got {value!r}")
    if not lo <= value <= hi:
        raise TrackballConfigError(f"{where} must be in [{lo}, {hi}], got {value!r}")
    return kind(value)


def _sensor(i: int, table: Any) -> SensorConfig:
    where = f"[[trackball.sensors]] #{i}"
    if not isinstance(table, dict):
        raise TrackballConfigError(f"{where} must be a table, got {table!r}")
    unknown = set(table) - _SENSOR_KEYS
    if unknown:
        raise TrackballConfigError(f"unknown key(s) {sorted(unknown)} in {where}; allowed: {sorted(_SENSOR_KEYS)}")
    if "azimuth_deg" not in table:
        raise TrackballConfigError(f"{where} needs azimuth_deg (degrees, 0 = front, 90 = left)")
    angles = {k: _number(f"{where} {k}", table.get(k, 0.0), float, -360.0, 360.0)
              for k in ("azimuth_deg", "elevation_deg", "roll_deg")}
    cpmm = table.get("counts_per_mm")  # None: the nominal value of resolution_cpi
    if cpmm is not None:
        if not isinstance(cpmm, (list, tuple)) or len(cpmm) != 2:
            raise TrackballConfigError(f"{where} counts_per_mm must be two numbers [x, y], got {cpmm!r}")
        cpmm = tuple(_number(f"{where} counts_per_mm", v, float, 1e-3, 1e5) for v in cpmm)
    cal_cpi = table.get("calibration_cpi")
    if cal_cpi is not None:
        if cpmm is None:
            raise TrackballConfigError(f"{where} has calibration_cpi but no counts_per_mm (it says which "
                                       "resolution the counts_per_mm were calibrated at)")
        cal_cpi = _number(f"{where} calibration_cpi", cal_cpi, int, *_TOP_KEYS["resolution_cpi"][1:])
    signs = table.get("signs", SensorConfig.signs)
    if not isinstance(signs, (list, tuple)) or len(signs) != 2 or any(s not in (1, -1) or isinstance(s, bool)
                                                                    for s in signs):
        raise TrackballConfigError(f"{where} signs must be two of +1 / -1 [x, y], got {signs!r}")
    return SensorConfig(counts_per_mm=cpmm, signs=tuple(int(s) for s in signs), calibration_cpi=cal_cpi, **angles)


def parse_section(section: dict[str, Any] | None, recalibrating: bool = False) -> TrackballConfig:
    """A `TrackballConfig` from a parsed `[trackball]` table (None or {} = all defaults).

    recalibrating: a sensor calibrated at another resolution than `resolution_cpi` (`calibration_cpi`) takes the
    nominal counts per mm instead of being refused: what `antarium trackball calibrate` reads before it measures
    them anew at `resolution_cpi`."""
    section = section or {}
    if not isinstance(section, dict):
        raise TrackballConfigError(f"[trackball] must be a table, got {section!r}")
    unknown = set(section) - set(_TOP_KEYS) - {"sensors"}
    if unknown:
        raise TrackballConfigError(
            f"unknown key(s) {sorted(unknown)} in [trackball]; allowed: {sorted([*_TOP_KEYS, 'sensors'])}"
        )
    values = {k: _number(f"[trackball] {k}", section[k], kind, lo, hi)
              for k, (kind, lo, hi) in _TOP_KEYS.items() if k in section}
    if "sensors" in section:
        sensors = section["sensors"]
        if not isinstance(sensors, list) or len(sensors) != N_SENSORS:
            raise TrackballConfigError(
                f"[trackball] sensors must be {N_SENSORS} [[trackball.sensors]] tables (one per sensor of the "
                f"report), got {sensors!r}"
            )
        values["sensors"] = tuple(_sensor(i, t) for i, t in enumerate(sensors))
        if recalibrating:
            cpi = values.get("resolution_cpi", DEFAULT_CPI)
            values["sensors"] = tuple(s if s.calibration_cpi in (None, cpi) else
                                      replace(s, counts_per_mm=None, calibration_cpi=None) for s in values["sensors"])
    config = TrackballConfig(**values)
    try:
        config.solver()
    except ValueError as exc:
        raise TrackballConfigError(f"[trackball] sensors: {exc}") from None
    return config


def to_section(config: TrackballConfig) -> dict[str, Any]:
    """The TOML table of `config` (inverse of `parse_section`)."""
    return {
        "vendor_id": config.vendor_id,
        "product_id": config.product_id,
        "ball_radius": config.ball_radius,
        "sample_rate_hz": config.sample_rate_hz,
        "resolution_cpi": config.resolution_cpi,
        "slip_floor_mm": config.slip_floor_mm,
        "sensors": [
            {"azimuth_deg": s.azimuth_deg, "elevation_deg": s.elevation_deg, "roll_deg": s.roll_deg,
             "counts_per_mm": list(s.counts_per_mm), "signs": list(s.signs),
             **({} if s.calibration_cpi is None else {"calibration_cpi": s.calibration_cpi})}
            for s in config.sensors
        ],
    }


def load(source: str | Path | dict[str, Any] | TrackballConfig | None, recalibrating: bool = False) -> TrackballConfig:
    """A `TrackballConfig` from a rig file path, a `[trackball]` table, a config, or None (defaults).

    A rig file's `[trackball]` without `ball_radius` takes the file's `[loop] ball_radius_m` (one ball, one radius).
    recalibrating: see `parse_section`.
    """
    if source is None or isinstance(source, TrackballConfig):
        return source or TrackballConfig()
    if isinstance(source, dict):
        return parse_section(source, recalibrating)
    if not isinstance(source, str | Path):
        raise TrackballConfigError(f"trackball config must be a rig file's path or a [trackball] table, got "
                                   f"{source!r}")
    from antarium.config import read_toml

    return parse_section(trackball_table(read_toml(Path(source))), recalibrating)


def write_section(path: str | Path, config: TrackballConfig) -> Path | None:
    """Write `config` as `[trackball]` of the rig file `path` (created if missing); returns the backup's path when
    the file had to be rewritten whole, None when only the calibration's keys changed.

    What a calibration changes, the sensors' `counts_per_mm` and `signs`, is replaced in place in the file's
    `[[trackball.sensors]]` tables (appended as such tables when the file has none), and every other byte of the
    file stays as it was, comments included. Anything else (other `[trackball]` keys changed, sensors written as
    an inline array, ...) rewrites the whole file with tomli-w, which keeps values but not comments: the previous
    file is first copied to `<path>.bak`. Every write is atomic (a temporary file, then a rename)."""
    import tomli_w

    path = Path(path)
    if not path.exists():
        _write_atomic(path, tomli_w.dumps({"trackball": to_section(config)}).encode())
        return None
    raw = path.read_bytes()
    from antarium.config import read_toml

    doc = read_toml(path)
    edited = _edit_calibration(raw.decode("utf-8"), doc, config)
    if edited is not None:
        _write_atomic(path, edited.encode("utf-8"))
        return None
    backup = path.with_name(path.name + ".bak")
    _write_atomic(backup, raw)
    doc["trackball"] = to_section(config)
    _write_atomic(path, tomli_w.dumps(doc).encode())
    return backup


def _write_atomic(path: Path, data: bytes) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_bytes(data)
    os.replace(tmp, path)


def _edit_calibration(text: str, doc: dict[str, Any], config: TrackballConfig) -> str | None:
    """`text` with the sensors' counts_per_mm and signs of `config` written in place, or None when the file's
    [trackball] differs from `config` in more than those, or its layout is not one edited safely here."""
    try:
        old = parse_section(trackball_table(doc), recalibrating=True)  # (a calibration at a new resolution)
    except TrackballConfigError:
        return None
    try:
        if len(old.sensors) != len(config.sensors) or replace(old, sensors=tuple(
                replace(o, counts_per_mm=n.counts_per_mm, signs=n.signs, calibration_cpi=n.calibration_cpi)
                for o, n in zip(old.sensors, config.sensors, strict=True))) != config:
            return None
    except TrackballConfigError:  # a calibration at another resolution than the file's
        return None
    values = [{"counts_per_mm": _toml_list(s.counts_per_mm), "signs": _toml_list(s.signs),
               **({} if s.calibration_cpi is None else {"calibration_cpi": str(s.calibration_cpi)})}
              for s in config.sensors]
    newline = "\r\n" if "\r\n" in text else "\n"
    try:
        entries = _top_level(text)
    except (ValueError, IndexError):
        return None
    headers = [k for k, e in enumerate(entries) if e[0] == "header"]
    sensor_headers = [k for k in headers if re.sub(r"\s", "", entries[k][1]) == "[[trackball.sensors]]"]
    table = doc.get("trackball", {})
    if not sensor_headers and isinstance(table, dict) and "sensors" not in table:
        if text and not text.endswith(("\n", "\r")):
            text += newline
        for s, v in zip(config.sensors, values, strict=True):
            text += newline.join(["", "[[trackball.sensors]]", f"azimuth_deg = {s.azimuth_deg!r}",
                                  f"elevation_deg = {s.elevation_deg!r}", f"roll_deg = {s.roll_deg!r}",
                                  f"counts_per_mm = {v['counts_per_mm']}", f"signs = {v['signs']}",
                                  *(f"{k} = {v[k]}" for k in ("calibration_cpi",) if k in v), ""])
        return _checked(text, doc, config)
    if len(sensor_headers) != len(config.sensors):
        return None
    edits: list[tuple[int, int, str]] = []  # (start, end, replacement), applied from the end
    for number, k in enumerate(sensor_headers):
        later = [h for h in headers if h > k]
        body = entries[k + 1: later[0] if later else len(entries)]
        missing = dict(values[number])
        for kind, key, start, end in body:
            if kind == "key" and key in missing:
                edits.append((start, end, missing.pop(key)))
        header_end = entries[k][3]
        line_end = text.find("\n", header_end)
        at = len(text) if line_end < 0 else line_end + 1
        for key, value in missing.items():  # a key the table leaves to its default: right below the header
            edits.append((at, at, f"{key} = {value}{newline}"))
    for start, end, replacement in sorted(edits, reverse=True):
        text = text[:start] + replacement + text[end:]
    return _checked(text, doc, config)


def _toml_list(values) -> str:
    return "[" + ", ".join(repr(v) for v in values) + "]"


def _checked(text: str, doc: dict[str, Any], config: TrackballConfig) -> str | None:
    """`text` when it parses to `doc` with only the sensors' calibration changed to `config`'s; None otherwise."""
    try:
        new = tomllib.loads(text)
        ok = parse_section(trackball_table(new)) == config
    except (tomllib.TOMLDecodeError, TrackballConfigError):
        return None
    rest = {k: v for k, v in new.items() if k != "trackball"} == {k: v for k, v in doc.items() if k != "trackball"}
    old_top = {k: v for k, v in doc.get("trackball", {}).items() if k != "sensors"}
    new_top = {k: v for k, v in new.get("trackball", {}).items() if k != "sensors"}
    return text if ok and rest and old_top == new_top else None


def _top_level(text: str) -> list[tuple[str, str, int, int]]:
    """The file's top-level entries in order: ("header", "[name]", start, end) or ("key", key, value_start,
    value_end); comments and blank lines are skipped. ValueError for what this small reader does not follow."""
    entries: list[tuple[str, str, int, int]] = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if c in " \t\r\n":
            i += 1
        elif c == "#":
            i = _line_end(text, i)
        elif c == "[":
            end = text.index("]", i + 1)
            end = end + 2 if text.startswith("]]", end) else end + 1
            entries.append(("header", text[i:end], i, end))
            i = _line_end(text, end)
        else:
            eq = text.find("=", i, _line_end(text, i))
            if eq < 0:
                raise ValueError(f"no '=' in {text[i:_line_end(text, i)]!r}")
            key = text[i:eq].strip()
            start = eq + 1
            while start < n and text[start] in " \t":
                start += 1
            end = _value_end(text, start)
            entries.append(("key", key, start, end))
            i = _line_end(text, end)
    return entries


def _line_end(text: str, i: int) -> int:
    end = text.find("\n", i)
    return len(text) if end < 0 else end + 1


def _value_end(text: str, i: int) -> int:
    """Where the TOML value starting at `i` ends (exclusive)."""
    for quote in ('"""', "'''"):
        if text.startswith(quote, i):
            end = text.index(quote, i + 3) + 3
            while end < len(text) and text[end] == quote[0]:
                end += 1
            return end
    c = text[i] if i < len(text) else ""
    if c == '"':
        j = i + 1
        while text[j] != '"':
            j += 2 if text[j] == "\\" else 1
        return j + 1
    if c == "'":
        return text.index("'", i + 1) + 1
    if c in "[{":
        depth, j = 0, i
        while True:
            ch = text[j]
            if ch in "[{":
                depth += 1
            elif ch in "]}":
                depth -= 1
                if depth == 0:
                    return j + 1
            elif ch == "#":
                j = _line_end(text, j) - 1
            elif ch in "\"'":
                j = _value_end(text, j) - 1
            j += 1
    end = i
    while end < len(text) and text[end] not in "#\r\n":
        end += 1
    return len(text[:end].rstrip(" \t"))
