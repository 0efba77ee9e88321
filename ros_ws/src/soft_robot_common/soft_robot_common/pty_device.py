"""A pseudo-terminal that stands in for a USB serial device, with unplug/replug.

The one emulated device of every emulator (the frog's relay in ``robot_emulator``, the
finger's Marlin board in ``marlin_emulator``). The controller side is ours; the device side is
linked to a stable path (``link_path``) that the host node opens like ``/dev/ttyACM0``.
"Unplug" closes the pair and removes the link (the host's reads then fail with EIO, as when
a USB device disappears); "replug" makes a new pair at the same path. The emulator's reading
thread selects on :attr:`PtyDevice.controller` and calls :meth:`PtyDevice.read`; where an
unplug can come from another thread (``marlin_emulator``'s ``~/unplug``), the reader takes an
``OSError`` or ``ValueError`` there as no data. Writes may come from any thread (they hold
:attr:`lock`).
"""

from __future__ import annotations

import errno
import fcntl
import os
import threading
import tty


class PtyDevice:
    """A pty pair whose device end is symlinked to ``link_path``."""

    def __init__(self, link_path: str):
        self.link_path = link_path
        self.lock = threading.Lock()
        self.controller: int | None = None
        self._device: int | None = None
        self.device_path = ""
        self.dropped_bytes = 0

    @property
    def plugged(self) -> bool:
        return self.controller is not None

    def plug(self) -> str:
        """Create a new pair and point ``link_path`` at its device; returns the device path."""
        with self.lock:
            if self.controller is not None:
                return self.device_path
            controller, device = os.openpty()
            tty.setraw(controller)
            tty.setraw(device)
            # a UART drops what nobody reads; never block the writer
            fcntl.fcntl(controller, fcntl.F_SETFL, fcntl.fcntl(controller, fcntl.F_GETFL) | os.O_NONBLOCK)
            path = os.ttyname(device)
            tmp = f"{self.link_path}.{os.getpid()}.tmp"
            if os.path.lexists(tmp):
                os.unlink(tmp)
            os.symlink(path, tmp)
            os.replace(tmp, self.link_path)          # atomic: the path never points nowhere
            self.controller, self._device, self.device_path = controller, device, path
            return path

    def unplug(self) -> None:
        """Close the pair and remove the link."""
        with self.lock:
            for fd in (self.controller, self._device):
                if fd is not None:
                    try:
                        os.close(fd)
                    except OSError:
                        pass
            self.controller = self._device = None
            try:
                if os.path.islink(self.link_path):
                    os.unlink(self.link_path)
            except OSError:
                pass

    # how long a non-blocking write waits for a line that another thread is writing
    LINE_WAIT_S = 0.1

    def write(self, data: bytes) -> int:
        """Write what fits now; the rest is dropped (counted). Returns bytes written.

        Waits at most :attr:`LINE_WAIT_S` for a :meth:`write_all` in progress (lines never
        interleave, as on the relay's UART); after that the line is dropped.
        """
        if not self.lock.acquire(timeout=self.LINE_WAIT_S):
            self.dropped_bytes += len(data)
            return 0
        try:
            if self.controller is None:
                self.dropped_bytes += len(data)
                return 0
            try:
                n = os.write(self.controller, data)
            except OSError as exc:
                if exc.errno not in (errno.EAGAIN, errno.EIO):
                    raise
                n = 0
            self.dropped_bytes += len(data) - n
            return n
        finally:
            self.lock.release()

    def write_all(self, data: bytes, timeout: float = 2.0) -> int:
        """Write all of ``data`` as one line, waiting for the reader up to ``timeout``.

        Returns the bytes written. Holds :attr:`lock` throughout, so other writes never land
        inside the line; call it from a worker thread, never from an executor callback.
        """
        import select
        import time
        end = time.monotonic() + timeout
        done = 0
        with self.lock:
            fd = self.controller
            while fd is not None and done < len(data) and time.monotonic() < end:
                try:
                    done += os.write(fd, data[done:done + 4096])
                    continue
                except OSError as exc:
                    if exc.errno not in (errno.EAGAIN, errno.EIO):
                        raise
                try:
                    select.select([], [fd], [], 0.05)
                except (OSError, ValueError):
                    break
            self.dropped_bytes += len(data) - done
        return done

    def read(self) -> bytes:
        """Read what is available (b"" if nothing; EIO while no one has the device open)."""
        fd = self.controller
        if fd is None:
            return b""
        try:
            return os.read(fd, 65536)
        except OSError as exc:
            if exc.errno in (errno.EAGAIN, errno.EIO):
                return b""
            raise


class OpenedDevice(PtyDevice):
    """An existing serial device (e.g. one end of ``socat``) used in place of a new pty.

    "Unplug" closes it, "replug" opens it again; ``link_path`` is not touched.
    """

    def __init__(self, device_path: str):
        super().__init__(link_path="")
        self.device_path = device_path

    def plug(self) -> str:
        with self.lock:
            if self.controller is None:
                fd = os.open(self.device_path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
                tty.setraw(fd)
                self.controller = fd
            return self.device_path

    def unplug(self) -> None:
        with self.lock:
            if self.controller is not None:
                try:
                    os.close(self.controller)
                except OSError:
                    pass
            self.controller = None
