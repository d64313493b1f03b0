"""The dome link's bit budget (docs/protocol.md section 1): what one frame and a polariser update cost on the wire.

Every datagram occupies, besides its UDP payload, 8 bytes of preamble/SFD, 14 of MAC header, 4 of FCS, 12 of
inter-frame gap and 28 of IP/UDP header (66 bytes); an IP packet shorter than 46 bytes is padded to 46 (the
84-byte LATCH). A frame (55 VIDEO datagrams and the LATCH) is 518,992 bits: at most 192.7 frames/s on
100 Mbit/s. A whole-dome POLARISER update adds 8,480 bits: frame + update every period allows only 189.6
frames/s, so at 190 frames/s an update goes out only where the link has room (`LinkBudget`).
"""

from __future__ import annotations

from antarium.geometry.constants import N_ACTUATORS, N_PANELS

from .header import CONTROL_HEADER_SIZE
from .video import VIDEO_PAYLOAD_SIZE

ETHERNET_BYTES = 8 + 14 + 4 + 12   # preamble/SFD, MAC header, FCS, inter-frame gap
IP_UDP_BYTES = 28
MIN_IP_PACKET_BYTES = 46           # the smallest Ethernet payload
DEFAULT_LINK_BPS = 100e6           # the dome's dedicated 100 Mbit/s Ethernet


def wire_bits(payload_bytes: int) -> int:
    """Bits one datagram with a UDP payload of `payload_bytes` occupies on the Ethernet link."""
    return 8 * (ETHERNET_BYTES + max(MIN_IP_PACKET_BYTES, IP_UDP_BYTES + payload_bytes))


FRAME_BITS = N_PANELS * wire_bits(VIDEO_PAYLOAD_SIZE) + wire_bits(CONTROL_HEADER_SIZE)   # 518,992
POLARISER_BITS = wire_bits(CONTROL_HEADER_SIZE + 2 * N_PANELS * N_ACTUATORS)               # 8,480


def max_frame_rate(link_bps: float = DEFAULT_LINK_BPS, extra_bits: int = 0) -> float:
    """Frames/s the link carries when each frame also carries `extra_bits` (e.g. POLARISER_BITS)."""
    return link_bps / (FRAME_BITS + extra_bits)


def max_rate_with_polarisers(link_bps: float = DEFAULT_LINK_BPS) -> float:
    """Frames/s above which a polariser update never fits `LinkBudget` (191.1 on 100 Mbit/s): an update may spill
    into the next period only as far as that frame still ends in time, so two periods must hold two frames and it."""
    return max_frame_rate(link_bps, POLARISER_BITS // 2)


class LinkBudget:
    """Whether a polariser update fits this frame period, sent after the frame's LATCH.

    An update may spill past the end of its period only as far as the next frame still ends within its own
    period; otherwise it is deferred (the caller tries again next period). Call `period(update_sent)` once a
    frame. Raises ValueError when the frames alone do not fit (`rate_hz` above `max_frame_rate`).
    """

    def __init__(self, rate_hz: float, link_bps: float = DEFAULT_LINK_BPS) -> None:
        limit = max_frame_rate(link_bps)
        if not rate_hz <= limit:
            raise ValueError(f"{rate_hz:g} frames/s do not fit a {link_bps / 1e6:g} Mbit/s dome link: at most "
                             f"{limit:.1f} frames/s ({FRAME_BITS:,} bits a frame)")
        self.period_bits = link_bps / rate_hz
        self.backlog = 0.0   # bits still on the wire when a period starts
        self.deferred = 0    # updates that had to wait a period

    def update_fits(self) -> bool:
        """Would a polariser update sent this period leave the next frame on time?"""
        spill = self.backlog + FRAME_BITS + POLARISER_BITS - self.period_bits
        return spill + FRAME_BITS <= self.period_bits

    def period(self, update_sent: bool, extra_bits: float = 0.0) -> None:
        """Account one frame period: its frame, the update if one went out, and `extra_bits` more sent in it (the
        held state the link sent again to a distributor that may have lost it: `Link.counters`'
        `state_resent_bits`), which the next frames wait behind."""
        sent = FRAME_BITS + (POLARISER_BITS if update_sent else 0) + extra_bits
        self.backlog = max(0.0, self.backlog + sent - self.period_bits)
