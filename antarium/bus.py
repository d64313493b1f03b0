"""The message bus (eclipse-zenoh): sessions from the `[bus]` config section, key names, stream structs.

Every key of a rig starts with `antarium/<rig>/` (see `docs/bus.md` for every key and payload).
Control traffic is JSON; high-rate streams are fixed little-endian structs starting with a version byte.

Sessions are peers without a router, with multicast scouting off. The server *listens* on the `[bus]
listen` endpoints (127.0.0.1 by default, so only this computer can reach it); clients (experiment
scripts, a trackball driver, a simulated ant) *connect* to `[bus] connect`, or to the server's listen
endpoints when that is empty, and listen nowhere themselves.

    session = open_session(config["bus"], role="client")
    locomotion_publisher(session, "rig1").put(wire.encode(sample))
"""

from __future__ import annotations

import json
import re
import socket
import struct
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from antarium.config import BusSection

KEY_ROOT = "antarium"



def check_key_chunk(value: str, what: str) -> str:
    """`value` if it is one key chunk (non-empty, without '/', wildcards, spaces or control characters, not starting
    with '@', which zenoh reads as a verbatim chunk that no wildcard matches), else ValueError naming `what`."""
    if not isinstance(value, str) or not value or value.startswith("@") or any(
            c in "/*?$# " or ord(c) < 32 for c in value):
        raise ValueError(f"{what} must be a non-empty key chunk without '/', '*', '?', '$', '#', ' ' or control "
                         f"characters, not starting with '@', got {value!r}")
    return value


def json_object(payload: bytes) -> dict | None:
    """A bus message's JSON object, or None for one that is not UTF-8 JSON, nested deeper than Python's JSON reader
    goes, or not an object (a subscriber skips it: a malformed message never reaches a callback)."""
    try:
        value = json.loads(payload)
    except (ValueError, RecursionError):  # UnicodeDecodeError included
        return None
    return value if isinstance(value, dict) else None


def check_rig_name(rig: str) -> str:
    """A rig name is one key chunk."""
    return check_key_chunk(rig, "rig name")


def rig_key(rig: str, *parts: str) -> str:
    """`antarium/<rig>/<parts...>`."""
    return "/".join((KEY_ROOT, check_rig_name(rig), *parts))


def locomotion_key(rig: str) -> str:
    """Where a trackball or a simulated ant publishes `antarium.locomotion.wire` structs (44 bytes each)."""
    return rig_key(rig, "locomotion")


def locomotion_publisher(session, rig: str):
    """The publisher for locomotion samples: express (no batching delay) and blocking rather than dropping
    when the link is congested, so that no ball rotation — no part of the ant's path — is silently lost."""
    import zenoh

    return session.declare_publisher(locomotion_key(rig), express=True,
                                     congestion_control=zenoh.CongestionControl.BLOCK)


def pose_key(rig: str) -> str:
    """The server's pose stream (`POSE_STRUCT`), every frame or every `[loop] pose_every` frames."""
    return rig_key(rig, "pose")


def stats_key(rig: str) -> str:
    """Frame statistics (`STATS_STRUCT`), every `[loop] stats_every` frames."""
    return rig_key(rig, "stats")


def status_key(rig: str) -> str:
    """Status (JSON) once a second."""
    return rig_key(rig, "status")


def events_key(rig: str) -> str:
    """Events (JSON): trial start/stop, link outage, locomotion lost/back, scene loaded, log errors."""
    return rig_key(rig, "events")


def command_key(rig: str, name: str) -> str:
    """Queryable of one command (JSON request in the query payload, JSON reply or error reply); the commands
    are those of `antarium.server.commands.COMMANDS`."""
    return rig_key(rig, "cmd", check_key_chunk(name, "command name"))


_ALIVE = ("alive", "server")


def alive_key(rig: str) -> str:
    """The server's liveliness token."""
    return rig_key(rig, *_ALIVE)


def any_alive_key() -> str:
    """The key expression of every rig's server liveliness token (`rig_of` gives each one's rig name)."""
    return "/".join((KEY_ROOT, "*", *_ALIVE))


def rig_of(key: str) -> str:
    """The rig name of a key `antarium/<rig>/...`."""
    return str(key).split("/")[1]


def session_config(bus: BusSection | dict[str, Any] | None, role: str = "server"):
    """A `zenoh.Config` from a `[bus]` section (typed, or a table with defaults filled in) for `role` "server"
    (listens) or "client" (connects)."""
    import zenoh

    if role not in ("server", "client"):
        raise ValueError(f"bus role must be 'server' or 'client', got {role!r}")
    from antarium.config import BusSection

    bus = BusSection.read(bus or {})
    conf = zenoh.Config()
    if bus.access_control and role == "server":  # the server enforces who may command the rig
        _insert_access_control(conf, Path(bus.access_control))
    conf.insert_json5("mode", json.dumps(bus.mode))
    conf.insert_json5("scouting/multicast/enabled", json.dumps(bus.multicast_scouting))
    listen, connect = bus.listen, bus.connect
    if role == "server":
        conf.insert_json5("listen/endpoints", json.dumps(listen))
        conf.insert_json5("connect/endpoints", json.dumps(connect))
    else:
        conf.insert_json5("listen/endpoints", json.dumps([]))
        conf.insert_json5("connect/endpoints", json.dumps(connect or listen))
    return conf


def _insert_access_control(conf, path: Path) -> None:
    """The ACL file `path` (a zenoh `access_control` object, JSON5) into `conf`; ValueError naming the file and
    what is wrong in it, at the line and column of the file itself."""
    try:
        text = path.read_text()
    except OSError as exc:
        raise ValueError(f"[bus] access_control file {str(path)!r} cannot be read: {exc}") from None
    try:
        conf.insert_json5("access_control", text)
    except Exception as exc:  # zenoh raises its own ZError for bad JSON5 or unknown fields
        raise ValueError(f"[bus] access_control file {str(path)!r} is not a valid zenoh ACL: "
                         f"{zenoh_message(exc)}") from None


def acl_missing_interfaces(path: str | Path) -> list[str]:
    """One line for each network interface the ACL file `path` names in a subject's `interfaces` that this computer
    does not have (`socket.if_nameindex`): no connection matches such a subject until the interface appears (a
    misspelt name, a card not plugged in). The file is read as `session_config` reads it (ValueError when it
    cannot be)."""
    import zenoh

    conf = zenoh.Config()
    _insert_access_control(conf, Path(path))
    have = sorted(name for _, name in socket.if_nameindex())
    lines = []
    for subject in json.loads(conf.get_json("access_control")).get("subjects") or []:
        for name in subject.get("interfaces") or []:
            if name not in have:
                lines.append(f"[bus] access_control subject {subject.get('id')!r} names the network interface "
                             f"{name!r}, which this computer does not have (it has {', '.join(have)}; `ip link`): "
                             "no connection matches that subject until it appears")
    return lines


def zenoh_message(exc: BaseException) -> str:
    """A zenoh error as one readable line: the message of a JSON5 error with its line and column, without the
    Rust source locations (`at /root/.cargo/...rs:86.`) zenoh appends."""
    text = str(exc)
    found = re.search(r'msg: "((?:[^"\\]|\\.)*)", location: Some\(Location \{ line: (\d+), column: (\d+)', text)
    if found:
        msg = json.loads(f'"{found[1]}"')
        msg = msg.rsplit("= ", 1)[-1] if "-->" in msg else msg  # a syntax error: pest's caret drawing, then "= what"
        return f"line {found[2]}, column {found[3]}: {msg.strip()}"
    return re.sub(r"\s+", " ", re.sub(r"\.? at /\S+\.rs:\d+\.?", "", text)).strip()


def open_session(bus: BusSection | dict[str, Any] | None = None, role: str = "server"):
    """Open a zenoh session from a `[bus]` section (defaults when None). See `session_config`."""
    import zenoh

    conf = session_config(bus, role)
    try:
        return zenoh.open(conf)
    except zenoh.ZError as exc:
        raise RuntimeError(f"cannot open the zenoh session (role {role}, [bus] {bus}): {zenoh_message(exc)}") from None


def free_tcp_endpoint(host: str = "127.0.0.1") -> str:
    """`tcp/<host>:<port>` with a port the OS reports free now (for tests and the embedded default)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return f"tcp/{host}:{s.getsockname()[1]}"


# --- high-rate stream structs (little-endian, version byte first) -------------------------------------

STREAM_VERSION = 1

#: pose: version u8, flags u8 (bit 0 closed loop, bit 1 fixed tether), reserved u16, frame u32,
#: t f64 (s, server clock), x y z f64 (m), heading f64 (rad), scene_rotation f64 (rad)
POSE_STRUCT = struct.Struct("<BBHIdddddd")  # 56 bytes

#: stats: version u8, reserved u8, reserved u16, frame u32, late_frames u32, reserved u32, t f64 (s),
#: latency, render, sample, encode, send, pacing_error f64 (s; latency NaN when no new sample)
STATS_STRUCT = struct.Struct("<BBHIIIddddddd")  # 72 bytes


#: the pose's flag bits this version defines (bit 0 closed loop, bit 1 fixed tether)
POSE_FLAGS = 0x03


class StreamError(ValueError):
    """A stream payload of the wrong size or version, or with reserved bits set."""


def _check_reserved(stream: str, flags: tuple[int, int] = (0, 0), reserved: int = 0) -> None:
    """StreamError when a payload sets flags outside `flags[1]` or a reserved field: a later version's meaning
    is refused, never misread as this one's."""
    if flags[0] & ~flags[1]:
        raise StreamError(f"{stream} payload flags 0x{flags[0]:02x} set bits this version does not define "
                          f"(allowed: 0x{flags[1]:02x})")
    if reserved:
        raise StreamError(f"{stream} payload reserved fields must be 0")


def encode_pose(frame: int, t: float, pose, scene_rotation: float, closed_loop: bool, fixed_tether: bool) -> bytes:
    flags = (1 if closed_loop else 0) | (2 if fixed_tether else 0)
    return POSE_STRUCT.pack(
        STREAM_VERSION, flags, 0, frame & 0xFFFFFFFF, t, pose.x, pose.y, pose.z, pose.heading, scene_rotation
    )


def decode_pose(payload: bytes) -> dict[str, Any]:
    """A pose payload as a dict: frame, t, x, y, z, heading, scene_rotation, closed_loop, fixed_tether."""
    if len(payload) != POSE_STRUCT.size:
        raise StreamError(f"pose payload must be {POSE_STRUCT.size} bytes, got {len(payload)}")
    version, flags, reserved, frame, t, x, y, z, heading, rot = POSE_STRUCT.unpack(payload)
    if version != STREAM_VERSION:
        raise StreamError(f"pose payload version {version} not supported (allowed: {STREAM_VERSION})")
    _check_reserved("pose", flags=(flags, POSE_FLAGS), reserved=reserved)
    return {
        "frame": frame, "t": t, "x": x, "y": y, "z": z, "heading": heading, "scene_rotation": rot,
        "closed_loop": bool(flags & 1), "fixed_tether": bool(flags & 2),
    }


def encode_stats(frame: int, late_frames: int, t: float, latency: float, render: float, sample: float,
                 encode: float, send: float, pacing_error: float) -> bytes:
    return STATS_STRUCT.pack(STREAM_VERSION, 0, 0, frame & 0xFFFFFFFF, late_frames & 0xFFFFFFFF, 0,
                             t, latency, render, sample, encode, send, pacing_error)


def decode_stats(payload: bytes) -> dict[str, Any]:
    if len(payload) != STATS_STRUCT.size:
        raise StreamError(f"stats payload must be {STATS_STRUCT.size} bytes, got {len(payload)}")
    version, r8, r16, frame, late, r32, t, latency, render, sample, encode, send, pacing = STATS_STRUCT.unpack(payload)
    if version != STREAM_VERSION:
        raise StreamError(f"stats payload version {version} not supported (allowed: {STREAM_VERSION})")
    _check_reserved("stats", reserved=r8 | r16 | r32)
    return {"frame": frame, "late_frames": late, "t": t, "latency": latency, "render": render, "sample": sample,
            "encode": encode, "send": send, "pacing_error": pacing}
