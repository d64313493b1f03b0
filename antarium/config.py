"""The rig configuration: TOML, one typed section per part, checked completely when it is loaded.

Each section is a pydantic model (`LoopSection`, `LinkSection`, ...) whose field names carry their units
(`eye_height_m`, `face_size_px`); `load_config(path)` / `resolve(raw)` return a `RigConfig` whose sections are
read as attributes (`config.loop.rate_hz`). Anything wrong (a file that cannot be read or is not UTF-8 TOML, an
unknown section or key, a wrong type, a value out of range) raises `ConfigError` with one line naming the file or
key and what is allowed, before anything starts. Keys renamed since (`[loop] eye_height` is now `eye_height_m`)
are still read, with a `ConfigDeprecationWarning` at their line of the file.
A section owned by another part (`[trackball]`) is kept as a table for that part to parse (a
`[trackball]` without `ball_radius` gets the loop's: the ball has one radius). With no file
the embedded default rig is used: emulator on loopback, default habitat, scripted walker in closed loop.
See `docs/rig.example.toml`.
"""

from __future__ import annotations

import math
import re
import tomllib
import warnings
from pathlib import Path
from typing import Any, ClassVar, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from antarium.core.ball import BALL_RADIUS_M, TETHERS
from antarium.core.rates import DOME_RATE_HZ


class ConfigError(ValueError):
    """A rig configuration that cannot be used; the message names the key and what is allowed."""


class ConfigDeprecationWarning(FutureWarning):
    """A config key read under its old name (shown by default: a lab should rename it)."""


class Section(BaseModel):
    """One `[section]`: unknown keys refused, no silent conversion (1 is not true, "5" is not 5)."""

    model_config = ConfigDict(extra="forbid", strict=True, validate_assignment=True)
    #: the section's name in the file
    NAME: ClassVar[str] = ""
    #: old key -> its name now (read with a deprecation warning)
    RENAMED: ClassVar[dict[str, str]] = {}
    #: key -> what it allows, where its type alone does not say (error messages and validators)
    ALLOWED: ClassVar[dict[str, str]] = {}

    @classmethod
    def read(cls, table: Any, source: tuple[str, str] | None = None) -> Section:
        """This section from a parsed TOML table (or a section already read); ConfigError if anything is wrong.
        source: (name, text) of the rig file it was read from, where a renamed key is warned about at its line."""
        if isinstance(table, cls):
            return table
        if not isinstance(table, dict):
            raise ConfigError(f"[{cls.NAME}] must be a table, got {table!r}")
        table = _renamed(cls, table, source)
        try:
            return cls.model_validate(table)
        except ValidationError as exc:
            raise ConfigError(_message(cls, exc, table)) from None


def _finite(lo: float, hi: float, default: float, doc: str = "") -> Any:
    return Field(default, ge=lo, le=hi, allow_inf_nan=False, description=doc)


class RigSection(Section):
    NAME: ClassVar[str] = "rig"
    name: str = Field("rig1", description="the bus key prefix is antarium/<name>/...")

    @field_validator("name")
    @classmethod
    def _one_key_chunk(cls, v: str) -> str:
        from antarium.core.log_names import RIG_NAME_MAX_BYTES

        if not v or any(c in v for c in "/*?$# "):
            raise ValueError("must be a non-empty key chunk without '/', wildcards or spaces")
        if len(v.encode()) > RIG_NAME_MAX_BYTES:  # it begins every trial log's file name, which has 255 bytes
            raise ValueError(f"must be at most {RIG_NAME_MAX_BYTES} bytes in UTF-8 (it begins the trial logs' file "
                             f"names <rig>_<yyyymmdd-hhmmss>_<trial>.h5, at most 255 bytes); this one has "
                             f"{len(v.encode())}")
        return v


class LoopSection(Section):
    NAME: ClassVar[str] = "loop"
    RENAMED: ClassVar[dict[str, str]] = {
        "start_x": "start_x_m", "start_y": "start_y_m", "eye_height": "eye_height_m", "ball_radius": "ball_radius_m",
        "stats_every": "stats_every_frames", "pose_every": "pose_every_frames"}
    rate_hz: float = _finite(1.0, 2000.0, DOME_RATE_HZ, "frames per second")
    closed_loop: bool = True
    tether: Literal[tuple(TETHERS)] = "free_yaw"  # type: ignore[valid-type]
    gain_translation: float = _finite(-100.0, 100.0, 1.0)
    gain_rotation: float = _finite(-100.0, 100.0, 1.0)
    start_x_m: float = _finite(-1e6, 1e6, 0.0, "virtual origin")
    start_y_m: float = _finite(-1e6, 1e6, 0.0)
    eye_height_m: float = _finite(0.0, 1000.0, 0.01, "the eye's z in the world (m): its height above a ground at "
                                  "z = 0 (a mesh scene's origin puts its ground there)")
    start_heading_deg: float = _finite(-3600.0, 3600.0, 0.0)
    ball_radius_m: float = _finite(1e-3, 1.0, BALL_RADIUS_M)
    stats_every_frames: int = Field(19, ge=1, le=100_000, description="publish frame statistics every N frames")
    pose_every_frames: int = Field(1, ge=1, le=100_000, description="publish the pose every N frames")
    realtime_priority: int = Field(10, ge=0, le=99, description="SCHED_FIFO for the frame loop (0: off)")
    cpu: int | str = Field("auto", description='a CPU for the frame loop alone: a number, "auto" or "off"')
    keep_gpu_busy: bool | Literal["auto"] = Field(
        "auto", description="small GPU work while waiting for a frame's slot, so that the GPU keeps its clocks; "
        '"auto": when the frame path runs on a hardware GPU')
    ALLOWED: ClassVar[dict[str, str]] = {"cpu": 'a CPU number (>= 0), "auto" or "off"',
                                         "keep_gpu_busy": 'true, false or "auto"'}

    @field_validator("cpu")
    @classmethod
    def _cpu(cls, v: int | str) -> int | str:
        if v in ("auto", "off") or (isinstance(v, int) and v >= 0):
            return v
        raise ValueError(f"must be {cls.ALLOWED['cpu']}")


class LocomotionSection(Section):
    """`source` names the back-end; every other key is passed to it as a keyword argument."""

    model_config = ConfigDict(extra="allow", strict=True, validate_assignment=True)
    NAME: ClassVar[str] = "locomotion"
    source: str = "scripted"

    @property
    def options(self) -> dict[str, Any]:
        """The keys passed on to the source."""
        return dict(self.model_extra or {})


class LinkSection(Section):
    NAME: ClassVar[str] = "link"
    interface: Literal["udp", "virtual"] = "udp"
    host: str = "127.0.0.1"
    port: int = Field(0, ge=0, le=65535, description="0 with spawn_emulator: a free port")
    spawn_emulator: bool = True
    brightness_percent: int = Field(100, ge=0, le=100, description=(
        "the panels' global LED current limit, sent at start and again to a distributor that rebooted"))
    dot_correction: int | str = Field(100, description=(
        "per-LED current percent, sent with brightness_percent: one for every LED, or a .npy file of them"))
    speed_mbit_s: float = _finite(1.0, 100_000.0, 100.0, "the dome link's line rate, Mbit/s: the frames' and "
                                  "polariser updates' bit budget (docs/protocol.md section 1)")
    ALLOWED: ClassVar[dict[str, str]] = {
        "dot_correction": "a whole percent 0..100 for every LED, or the path of a .npy file of percents, shape "
                          "(55, 740) or (20350, 2)"}

    @field_validator("dot_correction")
    @classmethod
    def _dot_correction(cls, v: int | str) -> int | str:
        if isinstance(v, str) and not v.endswith(".npy") or isinstance(v, int) and not 0 <= v <= 100:
            raise ValueError(f"must be {cls.ALLOWED['dot_correction']}")
        return v

    @model_validator(mode="after")
    def _port_of_a_distributor(self) -> LinkSection:
        if self.interface == "udp" and not self.spawn_emulator and self.port == 0:
            raise ValueError("port 0 needs spawn_emulator = true (the emulator's free port); allowed with "
                             "spawn_emulator = false: the distributor's UDP port 1..65535 (the board's is in "
                             "docs/rig.real.example.toml)")
        return self


class RenderSection(Section):
    NAME: ClassVar[str] = "render"
    RENAMED: ClassVar[dict[str, str]] = {"face_size": "face_size_px"}
    scene: str | dict[str, Any] = "habitat"
    face_size_px: int = Field(0, ge=0, le=2048, description="cube face side; 0: the renderer's default")
    far_layer: Literal["off", "sync", "async", "auto"] = Field(
        "auto", description='"auto": off on the GPU path (every mesh every frame), async on the CPU path')
    path: Literal["auto", "gpu", "cpu"] = Field(
        "auto", description="per-LED sampling, conversion and packing; auto: cpu on a software GL driver, else gpu")
    near_radius_m: float = _finite(0.01, 1000.0, 2.0)
    far_layer_error_deg: float = _finite(0.01, 5.0, 0.5)
    ALLOWED: ClassVar[dict[str, str]] = {"scene": "a scene name, a file path or a table with 'scene'"}

    @field_validator("scene")
    @classmethod
    def _scene(cls, v: str | dict) -> str | dict:
        if isinstance(v, dict) and "scene" not in v:
            raise ValueError(f"must be {cls.ALLOWED['scene']}")
        return v


#: the zenoh 1.x link protocols whose address is HOST:PORT (those the eclipse-zenoh wheel is built with; tls and
#: quic also need certificates under [bus] access_control's zenoh config)
ENDPOINT_IP_PROTOCOLS = ("tcp", "udp", "tls", "quic", "ws")
#: what `is_endpoint` accepts, in words (error messages)
ENDPOINT_FORMS = ("PROTOCOL/HOST:PORT with PROTOCOL one of " + ", ".join(ENDPOINT_IP_PROTOCOLS) + " and PORT "
                  "0..65535 (e.g. 'tcp/127.0.0.1:7447', '[::1]' for IPv6), or unixsock-stream/PATH")


def is_endpoint(endpoint: str) -> bool:
    """A zenoh locator `PROTOCOL/ADDRESS[?METADATA][#CONFIG]` with a protocol zenoh links and an address of its
    form: HOST:PORT (IPv6 hosts in brackets, PORT 0..65535) or, for unixsock-stream, a socket path."""
    if not isinstance(endpoint, str):
        return False
    proto, sep, address = endpoint.partition("/")
    address = address.split("#")[0].split("?")[0]
    if not sep or not address:
        return False
    if proto == "unixsock-stream":
        return True
    if proto not in ENDPOINT_IP_PROTOCOLS:
        return False
    host, colon, port = address.rpartition(":")
    if not colon or not host or not (port.isascii() and port.isdigit()) or int(port) > 65535:
        return False
    if host.startswith("["):
        return host.endswith("]") and ":" in host
    return ":" not in host and "/" not in host


class BusSection(Section):
    NAME: ClassVar[str] = "bus"
    enabled: bool = True
    mode: Literal["peer", "client", "router"] = "peer"
    listen: list[str] = Field(default_factory=lambda: ["tcp/127.0.0.1:7447"])
    connect: list[str] = Field(default_factory=list)
    multicast_scouting: bool = False
    access_control: str = Field("", description="path of a JSON5 file holding a zenoh access_control object")

    @field_validator("listen", "connect")
    @classmethod
    def _endpoints(cls, v: list[str]) -> list[str]:
        for endpoint in v:
            if not is_endpoint(endpoint):
                raise ValueError(f"{endpoint!r} is not a zenoh endpoint; allowed: {ENDPOINT_FORMS}")
        return v



class LogSection(Section):
    NAME: ClassVar[str] = "log"
    dir: str = Field("trials", description="the trial logs' folder; relative: to the server's working folder")
    flush_s: float = _finite(0.01, 1.0, 0.25, "seconds between flushes to disk")
    record: bool = False

    @field_validator("dir")
    @classmethod
    def _a_folder(cls, v: str) -> str:
        if not v.strip():  # "" would be the working folder, unsaid
            raise ValueError("must name a folder (\".\" for the server's working folder)")
        return v


class MonitorSection(Section):
    """The browser monitor (`antarium monitor`, docs/monitor.md)."""

    NAME: ClassVar[str] = "monitor"
    enabled: bool = Field(False, description="`antarium serve` starts the monitor as a process of its own")
    host: str = Field("127.0.0.1", description="address the web server listens on")
    port: int = Field(8050, ge=0, le=65535, description="TCP port; 0: one the OS chooses (printed)")
    allow: list[str] = Field(default_factory=lambda: ["127.0.0.1/32", "::1/128"],
                             description="addresses or networks whose browsers may open the page")
    commands: bool = Field(False, description="the page may send pause / rotate scene / start / stop trial")
    hosts: list[str] = Field(default_factory=list, description="more host names the page is opened by (a DNS "
                             "alias of this computer); its address, host name and localhost always serve")
    leds_every_frames: int = Field(5, ge=0, le=100_000, description="LED stream every N frames; 0: never")
    update_hz: float = _finite(1.0, 240.0, 60.0, "most updates a second pushed to each browser")
    RENAMED: ClassVar[dict[str, str]] = {"leds_every": "leds_every_frames"}

    @field_validator("allow")
    @classmethod
    def _networks(cls, v: list[str]) -> list[str]:
        import ipaddress

        if not v:  # the monitor would start and refuse every browser, its own computer's included
            raise ValueError("is empty: no browser could open the page; name at least one address or network "
                             "(e.g. '127.0.0.1/32')")
        out = []
        for spec in v:
            try:
                out.append(str(ipaddress.ip_network(spec, strict=False)))
            except ValueError:
                raise ValueError(f"{spec!r} is not an address or network (e.g. '127.0.0.1', '192.168.10.0/24')"
                                 ) from None
        return out


#: the sections this module checks, by name
SECTIONS: dict[str, type[Section]] = {s.NAME: s for s in (
    RigSection, LoopSection, LocomotionSection, LinkSection, RenderSection, BusSection, LogSection, MonitorSection)}
#: sections owned by another part, kept as tables for it to parse with its own code
FOREIGN_SECTIONS = ("trackball",)

#: the embedded default's walker, used when the config has no [locomotion] section: an ant-like scripted walk
#: (about 3 cm/s, in spurts, meandering), seeded so that every run is the same
DEFAULT_WALKER: dict[str, Any] = {"source": "scripted", "speed": 0.03, "meander": 0.6, "spurt_s": 0.8,
                                  "pause_fraction": 0.2, "seed": 1}


class RigConfig(BaseModel):
    """A whole rig config: one attribute per section; `foreign` holds the sections other parts parse."""

    model_config = ConfigDict(validate_assignment=True)
    rig: RigSection = Field(default_factory=RigSection)
    loop: LoopSection = Field(default_factory=LoopSection)
    locomotion: LocomotionSection = Field(default_factory=lambda: LocomotionSection.model_validate(DEFAULT_WALKER))
    link: LinkSection = Field(default_factory=LinkSection)
    render: RenderSection = Field(default_factory=RenderSection)
    bus: BusSection = Field(default_factory=BusSection)
    log: LogSection = Field(default_factory=LogSection)
    monitor: MonitorSection = Field(default_factory=MonitorSection)
    foreign: dict[str, dict[str, Any]] = Field(default_factory=dict)

    def section(self, name: str) -> dict[str, Any] | None:
        """A foreign section's table (`[trackball]`), or None when the file has none."""
        return self.foreign.get(name)

    def to_toml_dict(self) -> dict[str, Any]:
        """The config as TOML tables (what `--print-config` prints and every trial log stores)."""
        out: dict[str, Any] = {name: getattr(self, name).model_dump() for name in SECTIONS}
        out.update(self.foreign)
        return out


def resolve(raw: dict[str, Any], source: tuple[str, str] | None = None) -> RigConfig:
    """The config from a parsed TOML document: defaults filled in, every section checked. source: (name, text) of
    the rig file `raw` was parsed from (`load_config`), where a renamed key is warned about at its line."""
    if not isinstance(raw, dict):
        raise ConfigError(f"a rig config must be a table of sections, got {type(raw).__name__}")
    unknown = sorted(set(raw) - set(SECTIONS) - set(FOREIGN_SECTIONS))
    loose = [key for key in unknown if not _is_table(raw[key])]
    if loose:  # `rate_hz = 190.0` written above every [section] header
        owner = [name for name, cls in SECTIONS.items() if loose[0] in {*cls.model_fields, *cls.RENAMED}]
        raise ConfigError(f"{loose[0]} = {raw[loose[0]]!r} is above every section header; allowed: "
                          + (f"under [{owner[0]}]" if owner else "keys under a [section] header"))
    if unknown:
        raise ConfigError(f"unknown section [{unknown[0]}]; allowed: "
                          + ", ".join(f"[{s}]" for s in (*SECTIONS, *FOREIGN_SECTIONS)))
    sections = {name: cls.read(raw[name], source) for name, cls in SECTIONS.items() if name in raw}
    foreign = {}
    for name in FOREIGN_SECTIONS:
        if name in raw:
            if not isinstance(raw[name], dict):
                raise ConfigError(f"[{name}] must be a table, got {raw[name]!r}")
            foreign[name] = trackball_table(raw) if name == "trackball" else raw[name]
    config = RigConfig(**sections, foreign=foreign)
    _one_ball_radius(raw, config)
    return config


def _is_table(value: Any) -> bool:
    """A parsed TOML `[table]` or `[[array of tables]]` (not a key's value)."""
    return isinstance(value, dict) or isinstance(value, list) and bool(value) and all(
        isinstance(v, dict) for v in value)


def _loop_ball_radius(doc: dict[str, Any]) -> Any:
    """`[loop] ball_radius_m` (or its old name) of a parsed rig file as written, None where it sets none."""
    loop = doc.get("loop")
    return loop.get("ball_radius_m", loop.get("ball_radius")) if isinstance(loop, dict) else None


def trackball_table(doc: dict[str, Any]) -> dict[str, Any]:
    """The `[trackball]` table of a parsed rig file as the USB trackball driver reads it ({} without one): one
    without `ball_radius` takes the file's `[loop] ball_radius_m`, so that the driver and the loop use one radius."""
    table = doc.get("trackball", {})
    if not isinstance(table, dict) or "ball_radius" in table or _loop_ball_radius(doc) is None:
        return table
    return {**table, "ball_radius": _loop_ball_radius(doc)}


def _one_ball_radius(raw: dict[str, Any], config: RigConfig) -> None:
    """The ball has one radius, the frame loop's and the USB trackball driver's. `[trackball] ball_radius` (the
    hardware's), or that of the `[trackball]` in the file `[locomotion] trackball` names (source "usb"; the driver's
    default where that sets none), is the loop's unless `[loop]` sets it; a `[trackball]` here without one takes
    the loop's (`trackball_table`). Two different values are refused: the ant's motion would be scaled by their
    ratio."""
    given = {}  # where a radius is set -> its value as written
    if _loop_ball_radius(raw) is not None:
        given["[loop] ball_radius_m"] = config.loop.ball_radius_m
    trackball = config.section("trackball")
    if trackball is not None and "ball_radius" in trackball:
        given["[trackball] ball_radius"] = trackball["ball_radius"]
    path = config.locomotion.options.get("trackball")
    if config.locomotion.source == "usb" and isinstance(path, str):
        table = trackball_table(read_toml(path, "[locomotion] trackball file"))
        where = f"[trackball] ball_radius of {path!r}" + ("" if "ball_radius" in table else " (its default)")
        given[where] = table.get("ball_radius", BALL_RADIUS_M)
    radii = {}
    for where, value in given.items():
        try:
            radii[where] = LoopSection.read({"ball_radius_m": value}).ball_radius_m
        except ConfigError as exc:
            raise ConfigError(str(exc).replace("[loop] ball_radius_m", where)) from None
    if not radii:
        return
    (first, r), *rest = radii.items()
    for where, other in rest:
        if not math.isclose(r, other):
            raise ConfigError(f"{first} {r} m differs from {where} {other} m; allowed: one value (set it in "
                              "[trackball] only)")
    config.loop.ball_radius_m = r


def read_toml(path: str | Path, what: str = "rig config") -> dict[str, Any]:
    """A TOML file parsed; ConfigError naming it as `what` if it cannot be read, is not UTF-8 or is not TOML."""
    return _parse_toml(_read_text(path, what), path, what)


def _read_text(path: str | Path, what: str) -> str:
    """A TOML file's text; ConfigError naming it as `what` if it cannot be read or is not UTF-8."""
    where = f"{what} {str(path)!r}"
    try:
        data = Path(path).read_bytes()
    except FileNotFoundError:
        raise ConfigError(f"{where} not found") from None
    except IsADirectoryError as exc:  # the cause kept for `antarium --debug`
        raise ConfigError(f"{where} is a folder; give a file") from exc
    except NotADirectoryError as exc:
        raise ConfigError(f"{where} cannot be read: a part of the path is a file, not a folder") from exc
    except OSError as exc:
        raise ConfigError(f"{where} cannot be read ({exc.strerror or exc}); give a file this user can read") from exc
    try:
        text = data.decode()
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise ConfigError(f"{where} is not UTF-8 text (byte 0x{data[exc.start]:02x} at line {line}); allowed: a "
                          "TOML file in UTF-8") from None
    return text


def _parse_toml(text: str, path: str | Path, what: str) -> dict[str, Any]:
    """`text` parsed; ConfigError naming the file as `what` and the line tomllib stopped at if it is not TOML."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        at = re.search(r"\(at line (\d+), column \d+\)$", str(exc))  # tomllib counts "\n" only
        lines = text.split("\n")
        shown = f": {lines[int(at[1]) - 1].strip()!r}" if at and int(at[1]) <= len(lines) else ""
        raise ConfigError(f"{what} {str(path)!r} is not valid TOML: {exc}{shown}") from None


def load_config(path: str | Path | None = None) -> RigConfig:
    """The rig config from a TOML file, or the embedded default when `path` is None. A key under its old name is
    warned about at its line of the file (`rig.toml:12: ConfigDeprecationWarning: [loop] eye_height is ...`)."""
    if path is None:
        return resolve({})
    text = _read_text(path, "rig config")
    return resolve(_parse_toml(text, path, "rig config"), (str(path), text))


def _renamed(cls: type[Section], table: dict[str, Any], source: tuple[str, str] | None) -> dict[str, Any]:
    """`table` with old key names replaced by today's (warning once per key, at its line of the file `source`
    names); both given is an error."""
    if not cls.RENAMED or not set(table) & set(cls.RENAMED):
        return table
    out = dict(table)
    for old, new in cls.RENAMED.items():
        if old in out:
            if new in out:
                raise ConfigError(f"[{cls.NAME}] has both {old!r} and {new!r}; allowed: {new!r} only")
            message = f"[{cls.NAME}] {old} is deprecated: call it {new}"
            if source is None:
                warnings.warn(message, ConfigDeprecationWarning, stacklevel=4)
            else:
                line = _key_line(source[1], cls.NAME, old)
                warnings.warn_explicit(message, ConfigDeprecationWarning, source[0], line)
            out[new] = out.pop(old)
    return out


def _key_line(text: str, section: str, key: str) -> int:
    """The line number (from 1) of `key = ...` under `[section]` in a TOML text; that of `[section]` where the
    key is written otherwise (`section.key`, an inline table), 0 where neither is found."""
    header, found = None, 0
    for number, line in enumerate(text.split("\n"), 1):
        head = re.match(r"\s*\[\s*([^\[\]]+?)\s*\]", line)
        if head:
            header = head[1].strip('"\'')
            found = found or (number if header == section else 0)
        elif header == section and re.match(rf"\s*[\"']?{re.escape(key)}[\"']?\s*=", line):
            return number
    return found


def _message(cls: type[Section], exc: ValidationError, table: dict[str, Any]) -> str:
    """One line for the first error: the key, what is allowed, what was given."""
    err = exc.errors()[0]
    key = str(err["loc"][0]) if err["loc"] else ""
    where = f"[{cls.NAME}] {key}".rstrip()
    got = table.get(key, err.get("input"))
    kind = err["type"]
    field = cls.model_fields.get(key)
    if kind == "extra_forbidden":
        return f"unknown key {key!r} in [{cls.NAME}]; allowed: {', '.join(sorted(cls.model_fields))}"
    if kind in ("greater_than_equal", "less_than_equal") and field is not None:
        lo = next((m.ge for m in field.metadata if getattr(m, "ge", None) is not None), None)
        hi = next((m.le for m in field.metadata if getattr(m, "le", None) is not None), None)
        return f"{where} must be in [{lo}, {hi}], got {got!r}"
    if kind == "literal_error":
        return f"{where} must be one of {err['ctx']['expected'].replace(' or ', ', ')}, got {got!r}"
    if kind == "value_error":
        return f"{where} {err['ctx']['error']}" + (f", got {got!r}" if key else "")  # no key: the whole section
    if key in cls.ALLOWED:
        return f"{where} must be {cls.ALLOWED[key]}, got {got!r}"
    plain = {"bool_type": "true or false", "float_type": "a finite number", "finite_number": "a finite number",
             "int_type": "an integer", "string_type": "a string", "list_type": "a list of strings",
             "dict_type": "a table"}
    if kind in plain:
        if len(err["loc"]) > 1 and field is not None and "list" in str(field.annotation):
            return f"{where} must be a list of strings, got {got!r}"
        return f"{where} must be {plain[kind]}, got {got!r}"
    return f"{where}: {err['msg']}, got {got!r}"
