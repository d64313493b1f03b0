"""Who may open the monitor and what its page may do (the `[monitor]` section is `antarium.config.MonitorSection`)."""

from __future__ import annotations

import ipaddress

#: commands the page may send (when `commands = true`), validated by the server like any bus command
PAGE_COMMANDS = ("rotate_scene", "closed_loop", "trial_start", "trial_stop")


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
