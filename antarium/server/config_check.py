"""`check_config(config)`: everything `antarium serve` would find wrong only once it runs, found before anything
starts (scene names and files, the locomotion back-end and its options, face sizes, the dome's address, ports in
use). One line per problem: `ConfigError` naming the key, what was wrong and what is allowed. `serve`, the example
scripts' --start-server and `serve --print-config` (without the ports in use: what the file says, not this
machine's state) run it.
"""

from __future__ import annotations

import errno
import socket
from pathlib import Path

from antarium.config import ConfigError, RigConfig

#: scene parameters that name files which must exist
SCENE_FILE_KEYS = ("path", "panorama", "uv")
#: scenes built from their parameters alone, in milliseconds: `check_config` builds them to check the parameters
#: (the habitat's meshes, mesh and panorama files are left to the start: seconds)
CHEAP_SCENES = ("uniform", "horizon", "bars", "bar", "grating", "checkerboard", "sky")


def check_config(config: RigConfig, *, ports: bool = True) -> RigConfig:
    """Raise `ConfigError` for the first thing in `config` that `serve` could not use; return `config`. ports:
    also refuse a bus endpoint or emulator port that something on this computer holds now."""
    _check_scene(config.render.scene)
    _check_face_size(config.render.face_size_px)
    _check_rate(config.loop.rate_hz, config.link.speed_mbit_s)
    _check_dot_correction(config.link.dot_correction)
    if config.link.interface == "udp":
        check_link_host(config.link.host)
    _check_locomotion(config)
    _check_trackball(config)
    _check_monitor(config)
    if ports:
        _check_ports(config)
    return config


def check_link_host(host: str) -> None:
    """`[link] host` is an IP address, or a host name this computer resolves (a dotted quad out of range, such
    as 192.168.55.256, is no name: refused without a name lookup)."""
    import ipaddress

    allowed = ("allowed: the distributor's IP address (e.g. \"192.168.55.2\"; \"127.0.0.1\" for a spawned emulator) "
               "or a host name this computer resolves")
    try:
        ipaddress.ip_address(host)
        return
    except ValueError:
        pass
    if not host or host.replace(".", "").isdigit() or ":" in host:
        raise ConfigError(f"[link] host {host!r} is not an IP address; {allowed}")
    try:
        socket.getaddrinfo(host, None, type=socket.SOCK_DGRAM)
    except (socket.gaierror, UnicodeError) as exc:
        raise ConfigError(f"[link] host {host!r} is not an IP address and does not resolve as a host name "
                          f"({getattr(exc, 'strerror', None) or exc}); {allowed}") from None


def _check_dot_correction(value: int | str) -> None:
    from antarium.firmware_proto.config import read_dot_correction

    try:
        read_dot_correction(value)
    except ValueError as exc:
        raise ConfigError(f"[link] dot_correction: {exc}") from None


def _check_scene(spec: str | dict) -> None:
    from antarium.renderers.library import MESH_SUFFIXES, SCENES
    from antarium.renderers.panorama import IMAGE_SUFFIXES

    params = {"scene": spec} if isinstance(spec, str) else dict(spec)
    name = params.pop("scene")
    if not isinstance(name, str) or not name:
        raise ConfigError(f"[render] scene must be a scene name or a file path, got {name!r}")
    if name not in SCENES:
        suffix = Path(name).suffix.lower()
        if suffix not in MESH_SUFFIXES + IMAGE_SUFFIXES:
            raise ConfigError(f"[render] scene {name!r} is not a known scene or a scene file; allowed: "
                              f"{', '.join(SCENES)}, or a mesh ({', '.join(MESH_SUFFIXES)}) or panorama "
                              f"({', '.join(IMAGE_SUFFIXES)}) file")
        params["path"] = name
    for key in SCENE_FILE_KEYS:
        value = params.get(key)
        if isinstance(value, str) and not Path(value).is_file():
            raise ConfigError(f"[render] scene file {value!r} ({key}) does not exist; give an existing file")
    if name in CHEAP_SCENES:  # its parameters checked as the renderer will: built (no files, no meshes) and dropped
        from antarium.renderers.library import build_scene

        try:
            build_scene(spec)
        except ValueError as exc:
            raise ConfigError(f"[render] scene {name!r}: {exc}") from None


def _check_trackball(config: RigConfig) -> None:
    """A `[trackball]` section is read as `antarium trackball` and the usb source read it: its keys and values."""
    section = config.section("trackball")
    if section is None:
        return
    from antarium.locomotion.trackball.config import parse_section

    try:
        parse_section(section)
    except ValueError as exc:
        raise ConfigError(str(exc) if "[trackball]" in str(exc) else f"[trackball] {exc}") from None


def face_size_range() -> tuple[int, int]:
    """Cube face sides (texels) the renderer `serve` builds accepts (its LED footprint is the default, the pitch);
    0 in the config means its default."""
    from antarium.renderers.renderer import MAX_FACE_SIZE, smallest_face_size

    return smallest_face_size(), MAX_FACE_SIZE


def _check_rate(rate_hz: float, speed_mbit_s: float) -> None:
    """A rate whose frames fit the dome link of `speed_mbit_s` but leave no room for a polariser update: the
    polarisers would never move (`LinkBudget`). Above the link's frame limit the budget is off (no real dome:
    emulated benchmarks)."""
    from antarium.firmware_proto.budget import max_frame_rate, max_rate_with_polarisers

    bps = speed_mbit_s * 1e6
    with_polarisers, frames_only = max_rate_with_polarisers(bps), max_frame_rate(bps)
    if with_polarisers < rate_hz <= frames_only:
        raise ConfigError(f"[loop] rate_hz = {rate_hz:g} leaves no room on the {speed_mbit_s:g} Mbit/s dome link "
                          f"([link] speed_mbit_s) for a polariser update (the polarisers would never move); allowed: "
                          f"at most {with_polarisers:.1f} frames/s (190 is the dome's rate)")


def _check_face_size(size: int) -> None:
    lo, hi = face_size_range()
    if size != 0 and not lo <= size <= hi:
        raise ConfigError(f"[render] face_size_px = {size} is not a face size the renderer accepts; allowed: "
                          f"{lo}..{hi} texels, or 0 for its default")


def source_options(config: RigConfig, **runtime) -> dict:
    """The keyword arguments `antarium serve` opens the [locomotion] source with: its own options, then what other
    sections give it (the bus source the rig's name and [bus]; scripted and servosphere the loop's tether and ball
    radius, one ball for the source and the loop; usb its [trackball] section), then `runtime` (the clock) where
    not set."""
    options = config.locomotion.options
    source = config.locomotion.source
    if source == "bus":
        options.setdefault("rig", config.rig.name)
        options.setdefault("bus", config.bus)
    if source in ("scripted", "servosphere"):
        options.setdefault("tether", config.loop.tether)
        options.setdefault("ball_radius", config.loop.ball_radius_m)
    if source == "usb" and config.section("trackball") is not None:
        options.setdefault("trackball", config.section("trackball"))  # the driver parses its own section
    for key, value in runtime.items():
        options.setdefault(key, value)
    return options


def _check_locomotion(config: RigConfig) -> None:
    """The source is known and takes its options (`source_options`): it is built, so that its own checks run, and
    dropped, never started."""
    from antarium.locomotion import BACKENDS, open_source

    source = config.locomotion.source
    if source not in BACKENDS:
        raise ConfigError(f"[locomotion] source {source!r} is unknown; allowed: {', '.join(sorted(BACKENDS))}")
    options = source_options(config)
    if source == "replay" or source.endswith("-replay"):
        path = options.get("path")
        if isinstance(path, str) and not Path(path).is_file():
            raise ConfigError(f"[locomotion] path {path!r} does not exist; give the recording to replay")
    try:
        open_source(source, **options)
    except (TypeError, ValueError) as exc:  # an option it does not take, or a value it refuses
        raise ConfigError(str(exc) if str(exc).startswith("[") else f"[locomotion] {exc}") from None


def _check_monitor(config: RigConfig) -> None:
    """The monitor reads the rig's bus streams: it cannot run without the bus."""
    if config.monitor.enabled and not config.bus.enabled:
        raise ConfigError("[monitor] enabled = true needs the bus, but [bus] enabled = false: the monitor shows the "
                          "rig's bus streams; enable [bus] or set [monitor] enabled = false")


def _check_ports(config: RigConfig) -> None:
    """The bus' listen endpoints (TCP/UDP) and a fixed emulator port must be free on this computer."""
    if config.bus.enabled:
        for endpoint in config.bus.listen:
            proto, _, address = endpoint.partition("/")
            host, _, port = address.split("#")[0].rpartition(":")
            if proto not in ("tcp", "udp") or not port.isdigit() or int(port) == 0:
                continue
            if port_in_use(proto, host.strip("[]"), int(port)):
                raise ConfigError(f"[bus] listen endpoint {endpoint} is in use (another antarium serve?); set "
                                  "[bus] listen to another port, or stop the other server")
    link = config.link
    if link.interface == "udp" and link.spawn_emulator and link.port and port_in_use("udp", link.host, link.port):
        raise ConfigError(f"[link] port {link.port} on {link.host} is in use, so the emulator cannot listen there; "
                          "set [link] port to another port (0: a free one), or stop what uses it")


def port_in_use(proto: str, host: str, port: int) -> bool:
    """True when binding `proto` ("tcp"/"udp") `host`:`port` fails because something holds it."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    kind = socket.SOCK_STREAM if proto == "tcp" else socket.SOCK_DGRAM
    with socket.socket(family, kind) as s:
        if proto == "tcp":
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as zenoh: a closed socket's TIME_WAIT is free
        try:
            s.bind((host, port))
        except OSError as exc:
            return exc.errno == errno.EADDRINUSE
    return False
