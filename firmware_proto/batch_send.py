"""One system call for a frame's datagrams: Linux `sendmmsg(2)` through ctypes (Python's socket has no sendmmsg).

`MessageBatch` describes fixed buffers once (an iovec and an mmsghdr per datagram, pointing into them) and then
sends any leading run of them per call without allocating; ctypes releases the GIL during the call. Where
sendmmsg is missing (not Linux, no libc), `available()` is False and callers send one datagram at a time.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import os

import numpy as np


class _IoVec(ctypes.Structure):
    _fields_ = [("iov_base", ctypes.c_void_p), ("iov_len", ctypes.c_size_t)]


class _MsgHdr(ctypes.Structure):
    _fields_ = [("msg_name", ctypes.c_void_p), ("msg_namelen", ctypes.c_uint32),
                ("msg_iov", ctypes.POINTER(_IoVec)), ("msg_iovlen", ctypes.c_size_t),
                ("msg_control", ctypes.c_void_p), ("msg_controllen", ctypes.c_size_t), ("msg_flags", ctypes.c_int)]


class _MMsgHdr(ctypes.Structure):
    _fields_ = [("msg_hdr", _MsgHdr), ("msg_len", ctypes.c_uint)]


@functools.cache
def _sendmmsg():
    if not os.uname().sysname == "Linux":
        return None
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        fn = libc.sendmmsg
    except (OSError, AttributeError):
        return None
    fn.argtypes = [ctypes.c_int, ctypes.POINTER(_MMsgHdr), ctypes.c_uint, ctypes.c_int]
    fn.restype = ctypes.c_int
    return fn


def available() -> bool:
    """Whether sendmmsg can be called here (Linux with a C library that has it)."""
    return _sendmmsg() is not None


class MessageBatch:
    """Datagrams in fixed buffers, sent by `send(fd, count)` on a connected socket.

    buffers: C-contiguous uint8 arrays, one datagram each; they must outlive the batch and may be rewritten
    between sends (only their addresses are kept).
    """

    def __init__(self, buffers: list[np.ndarray]):
        for b in buffers:
            if not (isinstance(b, np.ndarray) and b.dtype == np.uint8 and b.flags.c_contiguous):
                raise ValueError("each datagram buffer must be a C-contiguous uint8 numpy array")
        self._buffers = buffers
        n = len(buffers)
        self._iov = (_IoVec * n)()
        self._msgs = (_MMsgHdr * n)()
        for k, b in enumerate(buffers):
            self._iov[k].iov_base = b.ctypes.data
            self._iov[k].iov_len = b.nbytes
            self._msgs[k].msg_hdr.msg_iov = ctypes.pointer(self._iov[k])
            self._msgs[k].msg_hdr.msg_iovlen = 1

    def __len__(self) -> int:
        return len(self._buffers)

    def send(self, fd: int, count: int | None = None) -> tuple[int, int]:
        """Send the first `count` datagrams (default all) in one call; returns (datagrams sent, errno). Fewer
        than asked (errno set: a full send buffer, a refusing peer) leaves the rest to the caller."""
        fn = _sendmmsg()
        if fn is None:
            raise RuntimeError("sendmmsg is not available on this system")
        count = len(self._buffers) if count is None else count
        sent = fn(fd, self._msgs, count, 0)
        if sent < 0:
            return 0, ctypes.get_errno()
        return sent, 0 if sent == count else ctypes.get_errno()
