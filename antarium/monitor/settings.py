"""The `[monitor]` section of a rig config: where the monitor listens, who may open it, what it may do."""

from __future__ import annotations

import ipaddress
from typing import Any

#: key -> default; the default's type is the type a value must have
DEFAULTS: dict[str, Any] = {
    "enabled": False,  # `antarium serve` starts the monitor as a process of its own
    "host": "127.0.0.1",  # address the web server listens on
    "port": 8050,  # TCP port; 0: one the OS chooses (printed)
    "allow": ["127.0.0.1/32", "::1/128"],  # addresses or networks whose browsers may open the page
    "commands": False,  # the page may send pause / rotate scene / start / stop trial
    "leds_every": 5,  # the server publishes the LED stream every N frames (190/5 = 38 Hz); 0: never
    "update_hz": 60.0,  # most updates a second pushed to each browser
}
#: commands the page may send (when `commands = true`), validated by the server like any bus command
PAGE_COMMANDS = ("rotate_scene", "closed_loop", "trial_start", "trial_stop")


def monitor_settings(config: dict[str, Any]) -> dict[str, Any]:
    """The resolved `[monitor]` section of a rig config (ValueError naming the key and what is allowed)."""
    raw = config.get("monitor", {}) or {}
    out = dict(DEFAULTS)
    for key, value in raw.items():
        if key not in DEFAULTS:
            raise ValueError(f"unknown key {key!r} in [monitor]; allowed: {', '.join(sorted(DEFAULTS))}")
        want = type(DEFAULTS[key])
        if want is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if not isinstance(value, want) or (want is int and isinstance(value, bool)):
            raise ValueError(f"[monitor] {key} must be a {want.__name__}, got {value!r}")
        out[key] = value
    if not 0 <= out["port"] <= 65535:
        raise ValueError(f"[monitor] port must be 0..65535, got {out['port']}")
    if not 0 <= out["leds_every"] <= 100000:
        raise ValueError(f"[monitor] leds_every must be 0..100000 frames, got {out['leds_every']}")
    if not 1.0 <= out["update_hz"] <= 240.0:
        raise ValueError(f"[monitor] update_hz must be 1..240, got {out['update_hz']}")
    out["allow"] = [str(network(a)) for a in out["allow"]]
    return out


def network(spec: str) -> ipaddress.IPv4Network | ipaddress.IPv6Network:
    try:
        return ipaddress.ip_network(spec, strict=False)
    except ValueError:
        raise ValueError(f"[monitor] allow: {spec!r} is not an address or network (e.g. '127.0.0.1', "
                         "'192.168.10.0/24')") from None


def allowed(address: str | None, allow: list[str]) -> bool:
    """True when `address` (a browser's IP) lies in one of the `allow` networks."""
    if not address:
        return False
    try:
        ip = ipaddress.ip_address(address.split("%")[0])
    except ValueError:
        return False
    if getattr(ip, "ipv4_mapped", None) is not None:
        ip = ip.ipv4_mapped
    return any(ip in network(a) for a in allow)
