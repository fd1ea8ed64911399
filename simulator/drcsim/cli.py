"""The drcsim command: serve, replay, selftest, bench, ladder, example-controller, worlds."""

from __future__ import annotations

import argparse
import json
import logging
import signal
import sys
from pathlib import Path
from typing import Any

from drcsim.controllers import CONTROLLERS
from drcsim.errors import DrcsimError
from drcsim.worlds import CONFIG_NAMES, WORLD_NAMES, load_world, read_world_file


def _sensor_settings(pairs: list[str]) -> Any:
    from drcsim.sensors import SensorSettings

    values = {}
    for pair in pairs:
        key, _, value = pair.partition("=")
        values[key] = value
    try:
        return SensorSettings.from_mapping(values)
    except (KeyError, ValueError) as exc:
        raise DrcsimError(f"bad --sensor setting: {exc}") from exc


def cmd_serve(args: argparse.Namespace) -> int:
    """Serve a world until its run ends or SIGTERM/SIGINT."""
    from drcsim.client import LOCAL_PORT_OFFSET
    from drcsim.engine import RunOptions, Simulation
    from drcsim.server import ServerSettings, SimServer

    options = RunOptions(
        log_dir=args.log_dir,
        world_document=read_world_file(args.world_file) if args.world_file else None,
        time_limit_s=args.time_limit,
        sensors=_sensor_settings(args.sensor),
        pose_rate_hz=args.pose_rate,
    )
    settings = ServerSettings(
        bind=args.bind,
        command_port=args.port,
        publish_port=args.publish_port or args.port + 1,
        local_port=args.local_port or args.port + LOCAL_PORT_OFFSET,
        allow=args.allow or ["127.0.0.1/32"],
        lockstep=args.lockstep,
        linger_s=args.linger,
    )
    sim = Simulation(args.world, args.config, options)
    server = SimServer(sim, settings)
    signal.signal(signal.SIGTERM, lambda *_: server.stop())
    signal.signal(signal.SIGINT, lambda *_: server.stop())
    print(
        f"drcsim: serving {args.world} config {args.config} on tcp://{args.bind}:{args.port} "
        f"(topics on {settings.publish_port}, ground truth on 127.0.0.1:{settings.local_port}, "
        f"lockstep={args.lockstep})",
        flush=True,
    )
    try:
        server.run()
    finally:
        server.close()
    print(
        json.dumps(
            {
                "end_reason": sim.scorer.end_reason,
                "score": sim.scorer.reached,
                "falls": sim.scorer.falls,
                "sim_time": sim.sim_time,
                "rejected": server.stats.rejected,
                "refused": server.stats.refused,
                "dropped": server.stats.dropped,
            }
        )
    )
    return 0


def cmd_replay(args: argparse.Namespace) -> int:
    """Re-simulate a logged run and check its final state."""
    from drcsim.replay import replay

    result = replay(args.log).as_dict()
    print(json.dumps(result) if args.json else f"replay OK: {result}")
    return 0


def cmd_selftest(args: argparse.Namespace) -> int:
    """Headless short run for provisioning checks."""
    from drcsim.bench import selftest

    result = selftest(args.world, args.config, args.seconds, not args.no_sensors, args.min_rtf)
    print(
        json.dumps(result)
        if args.json
        else f"{'OK' if result['ok'] else 'FAIL'} rtf={result['rtf']} falls={result['falls']}"
    )
    return 0 if result["ok"] else 1


def cmd_bench(args: argparse.Namespace) -> int:
    """Measure RTF per world with and without sensors, and the lock-step round trip."""
    from drcsim.bench import run_bench

    result = run_bench(args.seconds, args.samples, args.split)
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        target = result["target"]
        print(
            f"load average {result['load_average']['before']} -> {result['load_average']['after']}"
            f"; target: {target['on']} >= {target['rtf']} with every sensor"
        )
        for row in result["rtf"]:
            verdict = ""
            if row["sensors"]:
                verdict = (
                    f" x{row['cpu_vs_no_sensors']} cpu of no sensors"
                    f" {'meets' if row['meets_target'] else 'MISSES'} target"
                )
            print(
                f"{row['world']:<11} sensors={row['sensors']!s:<5} "
                f"cpu_rtf={row['cpu_rtf']:<6} wall_rtf={row['rtf']:<6}{verdict}"
            )
            if "cpu_ms_per_sim_s" in row:
                print(f"    cpu ms per simulated s: {row['cpu_ms_per_sim_s']}")
        print(f"target met: {target['met']}; round trip: {result['round_trip']}")
    return 0


def cmd_ladder(args: argparse.Namespace) -> int:
    """Run the reference controllers over the worlds and configurations; print the table."""
    from drcsim.ladder import run_ladder

    result = run_ladder(args.controller, args.world, args.config, args.time_limit, args.jobs)
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        for row in result["runs"]:
            print(
                f"{row['controller']:<8} {row['world']} {row['config']} "
                f"{row['checkpoints']}/4 falls={row['falls']} {row['reason']}"
            )
        for style, total in result["totals"].items():
            print(f"{style:<8} {total['checkpoints']}/{total['of']} falls={total['falls']}")
    return 0


def cmd_example(args: argparse.Namespace) -> int:
    """Run a reference team controller (the example one by default) against a server."""
    from drcsim.client import SimClient

    with SimClient(args.server, args.port, timeout_s=10.0) as client:
        controller = CONTROLLERS[args.style](
            client,
            log=lambda line: print(line, file=sys.stderr),
            timeout_s=args.timeout,
        )
        if args.world and controller.info["world"] != args.world:
            raise DrcsimError(f"the server runs {controller.info['world']}, not {args.world}")
        score = controller.run()
    print(json.dumps(score))
    return 0


def cmd_watch(args: argparse.Namespace) -> int:
    """Follow a running server's poses and score as JSON lines."""
    from drcsim.watch import watch

    watch(args.port, args.rate, args.seconds, local_port=args.local_port)
    return 0


def cmd_poses(args: argparse.Namespace) -> int:
    """Print a logged run's scene and its link poses rebuilt from the state log."""
    from drcsim.watch import print_log_frames

    print_log_frames(args.log, args.every)
    return 0


def cmd_worlds(_: argparse.Namespace) -> int:
    """List the worlds and their run configurations."""
    for name in WORLD_NAMES:
        for config in CONFIG_NAMES:
            spec = load_world(name, config)
            print(f"{name} {config} seed={spec.seed} start={list(spec.robot_start)}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser."""
    parser = argparse.ArgumentParser(prog="drcsim", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    serve = sub.add_parser("serve", help="serve a world over the network")
    serve.add_argument("--world", required=True, choices=WORLD_NAMES)
    serve.add_argument("--config", default="1", help="run configuration (1..5 when shipped)")
    serve.add_argument(
        "--world-file",
        type=Path,
        default=None,
        help="build the world from this document (JSON, checked) instead of the shipped copy",
    )
    serve.add_argument("--bind", default="127.0.0.1", help="address to listen on")
    serve.add_argument("--port", type=int, default=7700, help="command port")
    serve.add_argument("--publish-port", type=int, default=None, help="topics (default port+1)")
    serve.add_argument(
        "--local-port",
        type=int,
        default=None,
        help="ground-truth topics, on 127.0.0.1 only (default port+2)",
    )
    serve.add_argument("--allow", action="append", help="allowed client address or network")
    serve.add_argument("--lockstep", action="store_true", help="advance only on step commands")
    serve.add_argument("--log-dir", type=Path, default=None, help="where to write the run logs")
    serve.add_argument("--time-limit", type=float, default=None, help="simulated seconds")
    serve.add_argument("--sensor", action="append", default=[], help="sensor setting KEY=VALUE")
    serve.add_argument("--linger", type=float, default=1.0, help="seconds to serve after the end")
    serve.add_argument(
        "--pose-rate", type=float, default=30.0, help="Hz of the poses topic (simulated time)"
    )
    serve.set_defaults(func=cmd_serve)
    rep = sub.add_parser("replay", help="re-simulate a logged run and check it")
    rep.add_argument("log", type=Path)
    rep.add_argument("--json", action="store_true")
    rep.set_defaults(func=cmd_replay)
    test = sub.add_parser("selftest", help="headless short run (provisioning check)")
    test.add_argument("--world", default="vrc_task_2", choices=WORLD_NAMES)
    test.add_argument("--config", default="1", choices=CONFIG_NAMES)
    test.add_argument("--seconds", type=float, default=2.0)
    test.add_argument("--no-sensors", action="store_true")
    test.add_argument("--min-rtf", type=float, default=1.0)
    test.add_argument("--json", action="store_true")
    test.set_defaults(func=cmd_selftest)
    bench = sub.add_parser("bench", help="RTF per world and command round trip")
    bench.add_argument("--seconds", type=float, default=5.0)
    bench.add_argument("--samples", type=int, default=2000)
    bench.add_argument("--json", action="store_true")
    bench.add_argument(
        "--split", action="store_true", help="also the CPU time of each part of a step"
    )
    bench.set_defaults(func=cmd_bench)
    example = sub.add_parser("example-controller", help="run the example team controller")
    example.add_argument("--server", required=True)
    example.add_argument("--port", type=int, default=7700)
    example.add_argument("--world", choices=WORLD_NAMES)
    example.add_argument("--timeout", type=float, default=900.0, help="wall seconds")
    example.add_argument("--style", default="example", choices=list(CONTROLLERS))
    example.set_defaults(func=cmd_example)
    ladder = sub.add_parser("ladder", help="reference controllers x worlds x configurations")
    ladder.add_argument("--controller", action="append", choices=list(CONTROLLERS))
    ladder.add_argument("--world", action="append", choices=WORLD_NAMES)
    ladder.add_argument("--config", action="append", choices=CONFIG_NAMES)
    ladder.add_argument("--time-limit", type=float, default=600.0, help="simulated s per run")
    ladder.add_argument("--jobs", type=int, default=None, help="parallel runs (default: cores)")
    ladder.add_argument("--json", action="store_true")
    ladder.set_defaults(func=cmd_ladder)
    follow = sub.add_parser(
        "watch", help="print the poses and score of a server on this machine (loopback only)"
    )
    follow.add_argument("--port", type=int, default=7700, help="the server's command port")
    follow.add_argument("--local-port", type=int, default=None, help="its loopback topics port")
    follow.add_argument("--rate", type=float, default=10.0, help="frames per simulated second")
    follow.add_argument("--seconds", type=float, default=60.0, help="wall seconds to follow")
    follow.set_defaults(func=cmd_watch)
    poses = sub.add_parser("poses", help="print a logged run's scene and link poses")
    poses.add_argument("log", type=Path)
    poses.add_argument("--every", type=int, default=3, help="every Nth 100 Hz state record")
    poses.set_defaults(func=cmd_poses)
    worlds = sub.add_parser("worlds", help="list worlds and run configurations")
    worlds.set_defaults(func=cmd_worlds)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the drcsim command."""
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="drcsim %(levelname)s %(name)s: %(message)s")
    try:
        code: int = args.func(args)
    except DrcsimError as exc:
        print(f"drcsim: error: {exc}", file=sys.stderr)
        return 1
    return code


if __name__ == "__main__":
    sys.exit(main())
