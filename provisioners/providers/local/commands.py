"""Run system commands (ip, mount, ...) and turn failures into CommandError."""

import shlex
import subprocess

from provisioners.providers.local.errors import CommandError

COMMAND_TIMEOUT_SECONDS = 60.0


def run_command(argv: list[str], *, timeout: float = COMMAND_TIMEOUT_SECONDS) -> str:
    """Run argv without a shell and return its stdout; raise CommandError on failure."""
    try:
        completed = subprocess.run(
            argv,
            stdin=subprocess.DEVNULL,
            capture_output=True,
            text=True,
            timeout=timeout,
            check=False,
        )
    except (OSError, subprocess.TimeoutExpired) as error:
        raise CommandError(f"`{shlex.join(argv)}` could not run: {error}") from error
    if completed.returncode != 0:
        raise CommandError(
            f"`{shlex.join(argv)}` failed with exit status {completed.returncode}: "
            f"{completed.stderr.strip() or completed.stdout.strip()}"
        )
    return completed.stdout


def command_succeeds(argv: list[str], *, timeout: float = COMMAND_TIMEOUT_SECONDS) -> bool:
    """Run argv and say whether it exited 0 (for probes whose failure is an answer)."""
    try:
        completed = subprocess.run(
            argv,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            timeout=timeout,
            check=False,
        )
    except subprocess.TimeoutExpired:
        return False
    except OSError as error:
        raise CommandError(f"`{shlex.join(argv)}` could not run: {error}") from error
    return completed.returncode == 0
