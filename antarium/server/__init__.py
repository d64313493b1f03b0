"""The stimulus server: the frame loop, the command table and its handlers, status, trial logs, the emulator
process, and `Server`, which assembles them into a rig from its config."""

from antarium.server.server import Server, ServerError

__all__ = ["Server", "ServerError"]
