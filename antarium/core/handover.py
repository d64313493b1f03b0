"""Large objects handed from one process to another without copying them in the receiver.

`dump(obj)`, in the sender, pickles `obj` (protocol 5) with every contiguous buffer (numpy arrays) out of band,
writes those buffers into one file in shared memory (`/dev/shm`, else the temporary folder) and returns a small
`Handover` to send over a connection. `load(handover)`, in the receiver, maps that file, removes its name and
unpickles with the buffers as views of the mapping: no array is copied, so a receiver that must not stall (the
frame loop's process) builds only the objects' shells, in well under a millisecond for a 100 MB scene. The
memory is freed when the last array viewing it is.

    handover = dump(scene)          # child process
    conn.send(handover)
    scene = load(conn.recv())       # server process
"""

from __future__ import annotations

import mmap
import os
import pickle
import tempfile
from dataclasses import dataclass

#: byte alignment of each buffer in the file (a cache line: numpy's own alignment is never worse)
ALIGN = 64


@dataclass(frozen=True)
class Handover:
    """An object in transit: its pickle (in-band part), the file holding its buffers ("" when it has none) and
    each buffer's (offset, size) in bytes."""

    pickle: bytes
    path: str
    spans: tuple[tuple[int, int], ...]

    @property
    def nbytes(self) -> int:
        """Bytes of the buffers in the file."""
        return sum(size for _, size in self.spans)


def _folder() -> str:
    return "/dev/shm" if os.path.isdir("/dev/shm") and os.access("/dev/shm", os.W_OK) else tempfile.gettempdir()


def dump(obj, folder: str | None = None) -> Handover:
    """Pickle `obj` with its buffers written to a new file in `folder` (default: shared memory)."""
    buffers: list[pickle.PickleBuffer] = []
    data = pickle.dumps(obj, protocol=5, buffer_callback=buffers.append)
    if not buffers:
        return Handover(data, "", ())
    raws = [b.raw() for b in buffers]
    spans, end = [], 0
    for raw in raws:
        spans.append((end, raw.nbytes))
        end = -(-(end + raw.nbytes) // ALIGN) * ALIGN
    fd, path = tempfile.mkstemp(prefix="antarium-handover-", dir=folder or _folder())
    try:
        os.ftruncate(fd, max(end, 1))
        with mmap.mmap(fd, max(end, 1)) as mapped:
            for raw, (offset, size) in zip(raws, spans, strict=True):
                mapped[offset:offset + size] = raw
    except BaseException:
        os.unlink(path)
        raise
    finally:
        os.close(fd)
    return Handover(data, path, tuple(spans))


def load(handover: Handover, unlink: bool = True):
    """The object of a `Handover`, its buffers views of the mapped file; `unlink`: remove the file's name (the
    mapping stays), so that nothing is left behind whatever happens to either process afterwards."""
    if not handover.path:
        return pickle.loads(handover.pickle)
    fd = os.open(handover.path, os.O_RDWR)
    try:  # page tables filled now, in this call (which releases the interpreter lock), not at first touch
        mapped = mmap.mmap(fd, 0, flags=mmap.MAP_SHARED | getattr(mmap, "MAP_POPULATE", 0))
    finally:
        os.close(fd)
    if unlink:
        discard(handover)
    view = memoryview(mapped)
    return pickle.loads(handover.pickle, buffers=[view[offset:offset + size] for offset, size in handover.spans])


def discard(handover: Handover) -> None:
    """Remove the file of a `Handover` that will not be loaded (or is loaded already); safe twice."""
    if handover.path:
        try:
            os.unlink(handover.path)
        except FileNotFoundError:
            pass
