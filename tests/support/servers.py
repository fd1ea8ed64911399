"""Private Redis and PostgreSQL servers for the test session, stopped by their recorded PIDs."""

from __future__ import annotations

import os
import pwd
import shutil
import socket
import subprocess
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from cloudsim.runtime.redis_server import redis_command


def free_port() -> int:
    """Return a TCP port on 127.0.0.1 that is free right now."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def wait_for(condition: Callable[[], object], timeout: float, what: str) -> object:
    """Poll until condition() is truthy and return its value; fail with `what` after timeout."""
    deadline = time.monotonic() + timeout
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > deadline:
            raise TimeoutError(f"timed out after {timeout:.0f} s waiting for {what}")
        time.sleep(0.05)


def port_accepts(port: int) -> bool:
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=0.2):
            return True
    except OSError:
        return False


class RedisServer:
    """redis-server on a free loopback port with its data in a temporary folder."""

    def __init__(self, data_dir: Path, password: str | None = None) -> None:
        self.port = free_port()
        self.password = password
        # a password is what a Redis reached from other machines needs (see docs/scaling-out.md)
        auth = ["--requirepass", password] if password else []
        self.process = subprocess.Popen(
            [*redis_command(self.port, data_dir), *auth], stdout=subprocess.DEVNULL
        )
        try:
            wait_for(lambda: port_accepts(self.port), 15, "redis-server")
        except BaseException:
            self.stop()  # a Redis that never came up is not left running
            raise

    def url(self, db: int = 0, host: str = "127.0.0.1", port: int | None = None) -> str:
        auth = f":{self.password}@" if self.password else ""
        return f"redis://{auth}{host}:{port or self.port}/{db}"

    def stop(self) -> None:
        self.process.terminate()
        self.process.wait(10)


def bench_redis(folder: Path) -> RedisServer:
    """Start a bench's Redis in folder; remove the folder if it does not come up."""
    try:
        return RedisServer(folder / "redis")
    except BaseException:
        shutil.rmtree(folder, ignore_errors=True)  # a bench leaves no folder behind
        raise


class PostgresServer:
    """A throwaway PostgreSQL cluster (initdb) on a free port, run as the postgres user."""

    def __init__(self, password: str | None = None) -> None:
        """Start the cluster; with a password it also listens on 127.0.0.1, where every TCP
        login needs a password (SCRAM), as a server other machines reach must."""
        # Not under pytest's tmp_path: the postgres user cannot enter root's 0700 folders.
        root = Path(tempfile.mkdtemp(prefix="cloudsim-test-pg-"))
        initdb = shutil.which("initdb") or "/usr/lib/postgresql/15/bin/initdb"
        self.pg_ctl = str(Path(initdb).with_name("pg_ctl"))
        self.root = root
        self.data = root / "data"
        self.sockets = root / "sockets"
        self.port = free_port()
        user = pwd.getpwnam("postgres")
        for path in (root, self.sockets):
            path.mkdir(parents=True, exist_ok=True)
            os.chown(path, user.pw_uid, user.pw_gid)
        self.password = password
        auth = ["-A", "trust"]
        listen = "''"
        if password:
            # the socket stays the harness's (trust); TCP logins need the password
            auth = ["--auth-local=trust", "--auth-host=scram-sha-256"]
            listen = "'127.0.0.1'"
        self._as_postgres(
            [
                initdb,
                "-D",
                str(self.data),
                *auth,
                "-U",
                "postgres",
                "--no-sync",
                "-E",
                "UTF8",
            ]
        )
        options = (
            f"-p {self.port} -k {self.sockets} -c listen_addresses={listen} -c fsync=off "
            "-c synchronous_commit=off -c full_page_writes=off"
        )
        self._as_postgres(
            [
                self.pg_ctl,
                "-D",
                str(self.data),
                "-o",
                options,
                "-w",
                "-l",
                str(root / "server.log"),
                "start",
            ]
        )
        self.pid = int((self.data / "postmaster.pid").read_text().split()[0])

    def create_login_database(self, name: str, host: str = "127.0.0.1", port: int = 0) -> str:
        """Create a role and a database it owns, both called name, with the server's password;
        return the SQLAlchemy URL that logs in over TCP at host:port (default: this server)."""
        assert self.password, "a login over TCP needs a server started with a password"
        self._psql(f"CREATE ROLE \"{name}\" LOGIN PASSWORD '{self.password}'")
        self._psql(f'CREATE DATABASE "{name}" OWNER "{name}"')
        return f"postgresql+psycopg://{name}:{self.password}@{host}:{port or self.port}/{name}"

    def _psql(self, statement: str) -> None:
        psql = shutil.which("psql") or "psql"
        self._as_postgres(
            [psql, "-h", str(self.sockets), "-p", str(self.port), "-q", "-c", statement, "postgres"]
        )

    def _as_postgres(self, argv: list[str]) -> None:
        subprocess.run(
            ["runuser", "-u", "postgres", "--", *argv],
            check=True,
            stdout=subprocess.DEVNULL,
            cwd=self.root,
        )

    def create_database(self, name: str) -> str:
        """Create a database and return its SQLAlchemy URL."""
        psql = shutil.which("psql") or "psql"
        self._as_postgres(
            [
                psql,
                "-h",
                str(self.sockets),
                "-p",
                str(self.port),
                "-q",
                "-c",
                f'CREATE DATABASE "{name}"',
                "postgres",
            ]
        )
        return f"postgresql+psycopg://postgres@/{name}?host={self.sockets}&port={self.port}"

    def stop(self) -> None:
        self._as_postgres([self.pg_ctl, "-D", str(self.data), "-m", "immediate", "-w", "stop"])
        shutil.rmtree(self.root, ignore_errors=True)


@dataclass(frozen=True)
class MotoEndpoint:
    """Where the session's moto EC2 server listens (the one cloud API that is mocked)."""

    host: str
    port: int

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}"
