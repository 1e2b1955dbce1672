"""Python objects between two processes over a socket pair, read without long GIL holds.

The daemon receives each hot-swapped skill from its skill server process
(:mod:`sctd.runtime.skillserver`) this way. A skill of a large vector-field model is
megabytes of numpy arrays, and a reader that makes bytes of them (chunks joined, or one
``pickle.loads`` of the whole) copies them while holding the GIL: about 1 ms per MB,
time in which the daemon's tick thread cannot run. So a message is a pickle (protocol 5)
of the object with every contiguous buffer of at least :data:`OUT_OF_BAND` bytes (a
numpy array's data) left out of it and sent raw after it. The reader receives each such
buffer into an anonymous memory map of its own with one ``recv_into(..., MSG_WAITALL)``,
which holds the GIL neither while it waits nor while the kernel copies (a pipe would
hand the bytes over in chunks of its capacity, and the reader would take the GIL back
after each), and unpickles against the maps: the arrays are views of them, nothing large
is copied with the GIL held, and their pages are unmapped with the GIL released too
(CPython's ``mmap`` drops it around ``munmap``) when the last array on them goes. The
pickle itself, the object's structure, is the only part unpickled with the GIL held
(kilobytes for a skill).

Layout: ``HEADER`` (pickle bytes, number of buffers), one ``!Q`` length per buffer,
the pickle, the buffers. One message at a time per direction: callers that send from
several threads hold a lock around :func:`send`.
"""

from __future__ import annotations

import mmap
import pickle
import socket
import struct
from collections.abc import Callable
from typing import Any

HEADER = struct.Struct("!QI")  # pickle bytes, out-of-band buffers
_LENGTH = struct.Struct("!Q")
OUT_OF_BAND = 64 * 1024  # bytes: smaller buffers stay in the pickle
MAX_BUFFERS = 4096
MAX_MESSAGE = 1 << 30  # bytes of one message: beyond, the stream is not ours


def pair() -> tuple[socket.socket, socket.socket]:
    """A connected pair of Unix stream sockets: one end for each process (pass the
    child's with ``pass_fds`` and wrap it with :func:`from_fd`)."""
    return socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)


def from_fd(fd: int) -> socket.socket:
    """The socket of an inherited end of :func:`pair`."""
    return socket.socket(socket.AF_UNIX, socket.SOCK_STREAM, fileno=fd)


def send(sock: socket.socket, obj: Any) -> None:
    """Send ``obj`` as one message (blocking until all is sent).

    Raises
    ------
    OSError
        The other end is closed (``BrokenPipeError``) or the socket failing.
    """
    buffers: list[pickle.PickleBuffer] = []

    def out_of_band(buf: pickle.PickleBuffer) -> bool:
        with buf.raw() as raw:
            if raw.nbytes < OUT_OF_BAND:
                return True  # in the pickle
        buffers.append(buf)
        return False

    data = pickle.dumps(obj, protocol=5, buffer_callback=out_of_band)
    views = [buf.raw() for buf in buffers]
    try:
        sock.sendall(HEADER.pack(len(data), len(views)) + b"".join(_LENGTH.pack(v.nbytes) for v in views))
        sock.sendall(data)
        for v in views:
            sock.sendall(v)
    finally:
        for v in views:
            v.release()


def receive(sock: socket.socket, before_unpickle: Callable[[], None] | None = None) -> Any:
    """Receive one message (blocking) and return its object; ``before_unpickle()`` is
    called before a message with out-of-band buffers is unpickled (the one step that
    holds the GIL for a while: the caller may choose when it runs).

    Raises
    ------
    EOFError
        The other end closed (before or within a message).
    ValueError
        A header no message of :func:`send` has.
    """
    size, count = HEADER.unpack(_receive_bytes(sock, HEADER.size))
    if count > MAX_BUFFERS:
        raise ValueError(f"a message with {count} buffers")
    lengths = [n for (n,) in _LENGTH.iter_unpack(_receive_bytes(sock, _LENGTH.size * count))]
    if size + sum(lengths) > MAX_MESSAGE:
        raise ValueError(f"a message of {size + sum(lengths)} bytes")
    data = _receive_bytes(sock, size) if size < OUT_OF_BAND else _receive_mapped(sock, size)
    maps = [_receive_mapped(sock, n) for n in lengths]
    if maps and before_unpickle is not None:
        before_unpickle()
    return pickle.loads(data, buffers=maps)


def _receive_into(sock: socket.socket, view: memoryview) -> None:
    done, n = 0, view.nbytes
    while done < n:  # MSG_WAITALL returns early only on a signal or the end
        got = sock.recv_into(view[done:], n - done, socket.MSG_WAITALL)
        if got == 0:
            raise EOFError
        done += got


def _receive_bytes(sock: socket.socket, n: int) -> bytes:
    buf = bytearray(n)
    if n:
        _receive_into(sock, memoryview(buf))
    return bytes(buf)


def _receive_mapped(sock: socket.socket, n: int) -> mmap.mmap:
    """``n`` bytes into a fresh anonymous map (its pages are touched by the kernel's
    copy, inside ``recv_into``, with the GIL released)."""
    buf = mmap.mmap(-1, max(n, 1))
    with memoryview(buf) as view:
        _receive_into(sock, view[:n])
    return buf
