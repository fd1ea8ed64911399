"""A ProxyCommand that takes an argv and leaves no process behind."""

from __future__ import annotations

import os
import select
import subprocess
from collections.abc import Sequence

import paramiko

from provisioners.remote.ssh.errors import ConnectError

# a proxy that ignores SIGTERM gets this long before SIGKILL
_STOP_GRACE_SECONDS = 2.0


class ArgvProxyCommand(paramiko.ProxyCommand):
    """Carry the SSH stream over a child process's stdin/stdout."""

    def __init__(self, argv: Sequence[str]) -> None:
        # paramiko's own __init__ re-splits a string and leaves stderr on an unread pipe
        self.cmd = list(argv)
        try:
            self.process = subprocess.Popen(
                self.cmd,
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=subprocess.DEVNULL,
                bufsize=0,
                start_new_session=True,
            )
        except OSError as exc:
            # a missing proxy program will not appear by retrying: fail at once
            raise ConnectError(f"proxy command {self.cmd[0]!r} cannot start: {exc}") from exc
        self.timeout: float | None = None

    def recv(self, size: int) -> bytes:
        """Return up to size bytes; b"" once the proxy has exited (end of stream)."""
        stdout = self.process.stdout
        assert stdout is not None
        try:
            ready, _, _ = select.select([stdout], [], [], self.timeout)
            # unlike paramiko's version, do not spin on a proxy that closed its stdout
            data = os.read(stdout.fileno(), size) if ready else None
        except ValueError:
            # close() ran while paramiko's reader thread waited here: that is the end of stream
            return b""
        except OSError as exc:
            raise paramiko.ProxyCommandFailure(" ".join(self.cmd), exc.strerror) from exc
        if data is None:
            raise TimeoutError()  # paramiko polls with a timeout; it is not an error
        return data

    def close(self) -> None:
        """Stop the proxy process and reap it; the pipes stay open until release().

        paramiko's reader thread may still be inside recv(): with the process gone it reads
        end-of-stream and exits. Closing the pipes now could let a new connection reuse the
        descriptor under that thread's feet.
        """
        if self.process.returncode is None:
            self.process.terminate()
            try:
                self.process.wait(_STOP_GRACE_SECONDS)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()

    def release(self) -> None:
        """Close the pipes, once the transport that read them has stopped."""
        for pipe in (self.process.stdin, self.process.stdout):
            if pipe is not None:
                pipe.close()
