"""The ``jaxtrack`` command line.

``jaxtrack reproduce STUDY|all`` — reproduce the studies' printed numbers (table or JSON) and figures.
``jaxtrack design uniform|ho|gradient`` — sampling schedules for Ho's plant (table + PNG).
``jaxtrack demo`` — Monte Carlo of a 2-D constant-velocity tracker (table + PNG).
"""

from __future__ import annotations

import argparse
import json
import sys


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="jaxtrack", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    from . import _design, _reproduce

    _reproduce.add_parser(sub)
    _design.add_parser(sub)
    demo = sub.add_parser("demo", help="Monte Carlo of a 2-D constant-velocity tracker: RMSE/ANEES table and PNG")
    demo.add_argument("--runs", type=int, default=10_000, help="Monte Carlo runs (default 10000)")
    demo.add_argument("--steps", type=int, default=100, help="steps per run (default 100, τ = 1 s)")
    demo.add_argument("--seed", type=int, default=0, help="PRNG seed (default 0)")
    demo.add_argument("--chunk-size", type=int, default=2_000, help="runs per compiled batch")
    demo.add_argument("--out", default="results/demo", help="output folder for demo.png and demo.json")
    demo.add_argument("--json", action="store_true", help="print the table rows as JSON")
    demo.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    scale = demo.add_argument_group(
        "many devices and hosts",
        "Share the runs over devices (results identical to one device). Across hosts, start the "
        "same command once per host with --coordinator, --num-processes and --process-id.",
    )
    scale.add_argument("--devices", type=int, default=None,
                       help="split this CPU into N devices and share the runs over them")
    scale.add_argument("--coordinator", default=None, metavar="HOST:PORT",
                       help="address of process 0, for jax.distributed.initialize")
    scale.add_argument("--num-processes", type=int, default=None, help="processes in the job (one per host)")
    scale.add_argument("--process-id", type=int, default=None, help="this process's index, 0 … N−1")
    return parser


def _start_devices(args) -> bool:
    """Set up the devices before JAX starts; True when the runs are to be sharded."""
    import jax

    if args.devices is not None:
        if args.devices < 1:
            raise SystemExit("jaxtrack: --devices must be ≥ 1")
        jax.config.update("jax_num_cpu_devices", args.devices)
    multi = (args.coordinator, args.num_processes, args.process_id)
    if any(v is not None for v in multi):
        if any(v is None for v in multi):
            raise SystemExit("jaxtrack: --coordinator, --num-processes and --process-id go together")
        jax.distributed.initialize(coordinator_address=args.coordinator, num_processes=args.num_processes,
                                   process_id=args.process_id)
    return args.devices is not None or args.coordinator is not None


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    if args.command == "reproduce":
        from . import _reproduce

        return _reproduce.main(args)
    if args.command == "design":
        from . import _design

        return _design.run(args)
    if args.command == "demo":
        from ._demo import format_table, run_demo

        if args.runs < 2 or args.steps < 1:
            print("jaxtrack demo: --runs must be ≥ 2 and --steps ≥ 1", file=sys.stderr)
            return 2
        sharded = _start_devices(args)
        import jax

        from ..montecarlo import run_mesh

        mesh = run_mesh() if sharded else None
        lead = jax.process_index() == 0
        out = run_demo(args.runs, args.steps, args.seed, args.out, args.chunk_size,
                       not args.no_progress and lead, mesh=mesh, write=lead)
        if not lead:
            return 0
        if mesh is not None:
            print(f"runs shared over {mesh.devices.size} devices in {jax.process_count()} process(es)",
                  file=sys.stderr)
        if args.json:
            print(json.dumps(out["rows"], indent=2))
        else:
            print(format_table(out["rows"]))
            print(f"figure: {out['figure']}\ntable:  {out['table']}")
        return 0
    return 2


if __name__ == "__main__":
    raise SystemExit(main())
