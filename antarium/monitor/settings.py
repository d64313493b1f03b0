"""Who may open the monitor and what its page may do (the `[monitor]` section is `antarium.config.MonitorSection`)."""

from __future__ import annotations

import ipaddress

#: commands the page may send (when `commands = true`) and the parameters it may give each; the server validates
#: them like any bus command. Others (trial_start's `folder`: where on the rig the log is written) only over the bus.
PAGE_COMMANDS: dict[str, tuple[str, ...]] = {
    "rotate_scene": ("deg",),
    "closed_loop": ("on",),
    "trial_start": ("name", "metadata"),
    "trial_stop": (),
}
#: names of this computer a browser may open the monitor by (with its bind address, its host names and any IP
#: address); a page served under another name (DNS rebinding: an attacker's name pointed at this computer) is refused
LOCAL_NAMES = ("localhost", "localhost.localdomain", "ip6-localhost", "ip6-loopback")


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


def refused_params(name: str, params: dict) -> str | None:
    """Why the page may not send `params` with command `name` (a parameter not in `PAGE_COMMANDS`), or None."""
    extra = sorted(set(params) - set(PAGE_COMMANDS[name]))
    if not extra:
        return None
    return (f"{name}: {', '.join(map(repr, extra))} cannot be sent from the page; allowed: "
            f"{', '.join(PAGE_COMMANDS[name]) or 'no parameters'} (use the bus for the others)")


def served_names(host: str, extra: tuple[str, ...] | list[str] = ()) -> set[str]:
    """The host names (lower case) the monitor, bound to `host`, is opened by: `host` itself, `LOCAL_NAMES`, this
    computer's host name and fully qualified name, and `extra`. IP addresses are not listed: any is accepted."""
    import socket

    names = {host, *LOCAL_NAMES, *extra}
    try:
        names |= {socket.gethostname(), socket.getfqdn()}
    except OSError:
        pass
    return {n.lower().rstrip(".") for n in names if n}


def host_name(header: str) -> str:
    """The name or address in a Host header ("name:port", "[::1]:port", "name"), lower case, no trailing dot."""
    header = header.strip()
    if header.startswith("["):
        return header[1:].split("]", 1)[0].lower()
    if header.count(":") == 1:
        header = header.split(":", 1)[0]
    return header.lower().rstrip(".")


def foreign_host(header: str | None, names: set[str]) -> str | None:
    """Why a request's Host header names the monitor by a name it is not served under (`names`, from
    `served_names`), or None. An IP address is never refused: DNS rebinding needs a name."""
    if header is None:
        return None
    name = host_name(header)
    if _is_address(name) or name in names:
        return None
    return (f"the name {name!r} (Host header) is not one this monitor is served under; open it by this "
            f"computer's address or one of: {', '.join(sorted(n for n in names if not _is_address(n)))}")


def _is_address(name: str) -> bool:
    try:
        ipaddress.ip_address(name.split("%")[0])
        return True
    except ValueError:
        return False
