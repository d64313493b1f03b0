"""The Antarium's geometry: the dome solid, panels, LED layout and every LED's address (pure numpy).

    from antarium.geometry import load_dome
    dome = load_dome()          # cached; milliseconds
    dome.directions             # (20350, 3) unit vectors from the dome centre
"""

from .addressing import PixelAddress, address
from .constants import N_GB, N_PANELS, N_PIXELS, N_UV, PIXELS_PER_PANEL
from .dome import Dome, load_dome
from .layout import LayoutParams, PanelLayout, generate_layout, load_layout
from .solid import Solid

__all__ = [
    "Dome",
    "LayoutParams",
    "N_GB",
    "N_PANELS",
    "N_PIXELS",
    "N_UV",
    "PIXELS_PER_PANEL",
    "PanelLayout",
    "PixelAddress",
    "Solid",
    "address",
    "generate_layout",
    "load_dome",
    "load_layout",
]
