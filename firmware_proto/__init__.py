"""Wire formats of the dome, the distributor and panel emulator, LED-driver and actuator models.

Open a link with `antarium.firmware_proto.link.open_link("udp" | "virtual", ...)`; the protocol is specified in
docs/protocol.md. This package module stays import-light (no numpy) so that the CLI can read its defaults.
"""

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 19055  # UDP port of the distributor (and of `antarium emulate`): 190 frames/s, 55 panels
