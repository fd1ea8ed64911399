"""The csrouter command: `serve` (the daemon) and the orchestrator's control commands.

Exit status (csrouter.protocol): 0 done (status: healthy), 1 refused or failed, 3 the daemon
does not answer, 4 status: the daemon runs but reports faults.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from csrouter import __version__
from csrouter.bandwidth_log import run_span_lines
from csrouter.config import DEFAULT_CONFIG_PATH, MAX_LATENCY_MS, RouterConfig, load_config
from csrouter.control import request
from csrouter.errors import ConfigError, DaemonUnavailable, RouterError
from csrouter.protocol import (
    ARM,
    COUNTERS,
    DISARM,
    EXIT_DAEMON_DOWN,
    EXIT_FAILED,
    EXIT_UNHEALTHY,
    LOG_PATH,
    RUN_LOG,
    STATUS,
)


def main(argv: Sequence[str] | None = None) -> int:
    """Run one csrouter command."""
    args = _parser().parse_args(argv)
    try:
        config = load_config(args.config)
        if args.command == "serve":
            from csrouter.daemon import serve  # needs netfilterqueue; control commands do not

            logging.basicConfig(level=logging.INFO, format="%(levelname)s %(message)s")
            return serve(config)
        if args.command == LOG_PATH:
            print(config.bandwidth_log)
            return 0
        if args.command == RUN_LOG:
            return _run_log(config, args.run_id, args.started_at, args.ended_at)
        return _control(args, config)
    except DaemonUnavailable as exc:
        if getattr(args, "json", False) and args.command == STATUS:
            print(json.dumps({"daemon": "down", "healthy": False, "error": str(exc)}))
        print(f"csrouter: {exc}", file=sys.stderr)
        return EXIT_DAEMON_DOWN
    except RouterError as exc:
        print(f"csrouter: {exc}", file=sys.stderr)
        return EXIT_FAILED


def _control(args: argparse.Namespace, config: RouterConfig) -> int:
    message: dict[str, Any] = {"op": args.command}
    if args.command == ARM:
        message.update(
            latency_ms=args.latency_ms,
            uplink_bits=args.uplink_bits,
            downlink_bits=args.downlink_bits,
            run_id=args.run_id,
        )
    answer = request(config.socket, message)
    if args.json:
        print(json.dumps(answer, indent=2, sort_keys=True))
    else:
        _print_text(answer)
    if args.command == STATUS and not answer.get("healthy", False):
        return EXIT_UNHEALTHY
    return 0


def _run_log(config: RouterConfig, run_id: str, started_at: float, ended_at: float) -> int:
    """Print the run's lines of the bandwidth log (the current one and the one before it)."""
    current = Path(config.bandwidth_log)
    lines: list[str] = []
    for path in (current.with_name(current.name + ".1"), current):
        if path.exists():
            lines += path.read_text(errors="replace").splitlines()
    cut = run_span_lines(lines, run_id, started_at, ended_at)
    if not cut:
        print(f"csrouter: no bandwidth log of run {run_id}", file=sys.stderr)
        return EXIT_FAILED
    sys.stdout.write("".join(line + "\n" for line in cut))
    return 0


def _print_text(answer: dict[str, Any], indent: str = "") -> None:
    for key, value in answer.items():
        if isinstance(value, dict):
            print(f"{indent}{key}:")
            _print_text(value, indent + "  ")
        else:
            print(f"{indent}{key}: {value}")


def _non_negative(text: str) -> int:
    value = int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text} is negative")
    return value


def _latency(text: str) -> int:
    value = int(text)
    if not 0 <= value <= MAX_LATENCY_MS:
        raise argparse.ArgumentTypeError(f"latency must be 0-{MAX_LATENCY_MS} ms")
    return value


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="csrouter", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=__version__)
    parser.add_argument("--config", default=DEFAULT_CONFIG_PATH, help="configuration file")
    commands = parser.add_subparsers(dest="command", required=True)
    commands.add_parser("serve", help="run the daemon (under systemd)")
    arm = commands.add_parser(ARM, help="start a run: latency, caps, counters to zero")
    arm.add_argument("--latency-ms", type=_latency, required=True)
    arm.add_argument("--uplink-bits", type=_non_negative, help="cap OCU->LAN (default: none)")
    arm.add_argument("--downlink-bits", type=_non_negative, help="cap LAN->OCU (default: none)")
    arm.add_argument("--run-id", help="the orchestrator's name for the run")
    for name, text in (
        (DISARM, "end the run: lift the caps, print the final counters"),
        (COUNTERS, "print the run's counters"),
        (STATUS, "print the daemon's health (exit 3: down, 4: faults)"),
    ):
        commands.add_parser(name, help=text)
    for sub in commands.choices.values():
        sub.add_argument("--json", action="store_true", help="print JSON")
    commands.add_parser(LOG_PATH, help="print the bandwidth log's path")
    run_log = commands.add_parser(RUN_LOG, help="print a run's bandwidth log cut to a span")
    run_log.add_argument("--run-id", required=True)
    run_log.add_argument("--from", dest="started_at", type=float, required=True, help="epoch s")
    run_log.add_argument("--to", dest="ended_at", type=float, required=True, help="epoch s")
    return parser


if __name__ == "__main__":
    try:
        sys.exit(main())
    except ConfigError as exc:
        print(f"csrouter: {exc}", file=sys.stderr)
        sys.exit(EXIT_FAILED)
