"""Antarium: stimulus server for the LED-dome virtual reality of insect navigation research.

`import antarium` stays light: GL, USB and zenoh are imported only by the modules that need them.
The experiment-script API (`antarium.Rig`) is resolved lazily on first use.
"""

from importlib import import_module

__version__ = "0.1.0"

# Public names resolved on first attribute access, so that importing the package never pulls in
# zenoh, moderngl or pyusb.
_LAZY = {
    "Pose": "antarium.core.pose",
    "Rig": "antarium.client",
}


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'antarium' has no attribute {name!r}")
    return getattr(import_module(module), name)


__all__ = ["__version__", *_LAZY]
