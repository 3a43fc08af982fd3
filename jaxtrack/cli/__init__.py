"""The ``jaxtrack`` command line.

``jaxtrack reproduce STUDY|all`` — reproduce the studies' printed numbers (table or JSON) and figures.
``jaxtrack design uniform|ho|gradient`` — sampling schedules for Ho's plant (table + PNG).
``jaxtrack demo`` — Monte Carlo of a 2-D constant-velocity tracker (table + PNG).

Arguments are checked before any computation (types, ranges, a writable ``--out``): a bad one
gives a one-line error on stderr and exit status 2. Ctrl-C stops a command within about a second
of device work, prints ``jaxtrack: interrupted`` and exits with status 130; files are written to
a temporary name and renamed, so an interrupted command leaves no partial file. A Ctrl-C that
would be lost (inside JAX's garbage-collector callback) is delivered again, and a command still
running 3 s after Ctrl-C, or given a second Ctrl-C, is ended with status 130 (``_interrupt``).
"""

from __future__ import annotations

import json
import os
import sys

from ._args import ArgumentError, OneLineParser, check_out_dir, fail, int_in, seed_limit


def _parser() -> OneLineParser:
    parser = OneLineParser(prog="jaxtrack", description=__doc__.splitlines()[0])
    from .. import __version__

    # argparse prints "jaxtrack 0.1.0" on stdout and exits 0 (main turns the SystemExit into 0).
    parser.add_argument("--version", action="version", version=f"jaxtrack {__version__}")
    parser.add_argument("--no-compilation-cache", action="store_true",
                        help="do not keep compiled programs on disk (default: JAXTRACK_CACHE_DIR, else "
                             "~/.cache/jaxtrack/jax; JAXTRACK_CACHE_DIR=off turns it off too)")
    sub = parser.add_subparsers(dest="command", required=True)
    from . import _design, _reproduce

    _reproduce.add_parser(sub)
    _design.add_parser(sub)
    demo = sub.add_parser("demo", help="Monte Carlo of a 2-D constant-velocity tracker: RMSE/ANEES table and PNG")
    demo.add_argument("--runs", type=int_in(2), default=10_000, help="Monte Carlo runs, ≥ 2 (default 10000)")
    demo.add_argument("--steps", type=int_in(1), default=100, help="steps per run, ≥ 1 (default 100, τ = 1 s)")
    demo.add_argument("--seed", type=int_in(0), default=0, help="PRNG seed, 0 … 2⁶³−1 (2³²−1 in float32; default 0)")
    demo.add_argument("--chunk-size", type=int_in(1), default=2_000, help="runs between progress updates, ≥ 1")
    demo.add_argument("--out", default="results/demo", help="output folder for demo.png and demo.json")
    demo.add_argument("--json", action="store_true", help="print the table rows as JSON")
    demo.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    scale = demo.add_argument_group(
        "many devices and hosts",
        "Share the runs over devices (results identical to one device). Across hosts, start the "
        "same command once per host with --coordinator, --num-processes and --process-id.",
    )
    scale.add_argument("--devices", type=int_in(1), default=None,
                       help="split this CPU into N devices and share the runs over them")
    scale.add_argument("--coordinator", default=None, metavar="HOST:PORT",
                       help="address of process 0, for jax.distributed.initialize")
    scale.add_argument("--num-processes", type=int_in(1), default=None, help="processes in the job (one per host)")
    scale.add_argument("--process-id", type=int_in(0), default=None, help="this process's index, 0 … N−1")
    return parser


def _check_demo(args) -> str | None:
    """Cross-argument checks of ``demo`` that argparse types cannot make; the message or None."""
    limit = seed_limit()
    if args.seed > limit:
        return f"argument --seed: must be ≤ {limit}, got {args.seed}"
    multi = (args.coordinator, args.num_processes, args.process_id)
    if any(v is not None for v in multi):
        if any(v is None for v in multi):
            return "--coordinator, --num-processes and --process-id go together"
        if args.process_id >= args.num_processes:
            return f"argument --process-id: must be in [0, {args.num_processes - 1}], got {args.process_id}"
        host, _, port = args.coordinator.rpartition(":")
        if not host or not port.isdigit() or not 1 <= int(port) <= 65535:
            return f"argument --coordinator: expected HOST:PORT with a port in [1, 65535], got {args.coordinator!r}"
    return None


def _start_devices(args) -> bool:
    """Set up the devices before JAX starts; True when the runs are to be sharded."""
    import jax

    if args.devices is not None:
        jax.config.update("jax_num_cpu_devices", args.devices)
    if args.coordinator is not None:
        jax.distributed.initialize(coordinator_address=args.coordinator, num_processes=args.num_processes,
                                   process_id=args.process_id)
    return args.devices is not None or args.coordinator is not None


def _run(args) -> int:
    if args.command == "reproduce":
        from . import _reproduce

        return _reproduce.main(args)
    if args.command == "design":
        from . import _design

        return _design.run(args)
    if args.command == "demo":
        from ._demo import format_table, json_document, run_demo

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
            print(json.dumps(json_document(out["rows"]), indent=2))
        else:
            print(format_table(out["rows"]))
            print(f"figure: {out['figure']}\ntable:  {out['table']}")
        return 0
    return 2


def main(argv: list[str] | None = None) -> int:
    """Run the command line on ``argv`` (default ``sys.argv[1:]``); returns the exit status.

    **Returns:** 0 on success, 1 when ``reproduce`` misses a paper number, 2 for a bad argument
    (one line on stderr, nothing computed), 130 on Ctrl-C.
    """
    # The command line proper (argv None) takes Ctrl-C over before anything heavy is imported:
    # JAX's garbage-collector callback would otherwise swallow a KeyboardInterrupt (_interrupt).
    guard = None
    if argv is None:
        from . import _interrupt

        guard = _interrupt.install()
    try:
        return _main(argv)
    except KeyboardInterrupt:
        return _interrupted(argv)
    except Exception:
        # A Ctrl-C that reached us as another error (raised inside a callback that XLA wraps).
        if guard is not None and guard.requested:
            return _interrupted(argv)
        raise


def _interrupted(argv) -> int:
    print("jaxtrack: interrupted", file=sys.stderr)
    if argv is None:
        # The command line proper: leave at once. A normal interpreter exit waits on (and
        # has crashed in) JAX's compiler and device threads torn down mid-call; the files
        # have been cleaned up already (they are written to temporary names and renamed).
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(130)
    return 130


def _main(argv) -> int:
    parser = _parser()
    try:
        args = parser.parse_args(argv)
    except ArgumentError as exc:
        print(exc, file=sys.stderr)
        return 2
    except SystemExit as exc:  # --help, --version
        return exc.code if isinstance(exc.code, int) else 0
    prog = f"jaxtrack {args.command}"
    if args.command == "demo" and (msg := _check_demo(args)):
        return fail(prog, msg)
    if args.command == "design":
        from ._design import check_args

        if msg := check_args(args):
            return fail(prog, msg)
    if msg := check_out_dir(args.out):
        return fail(prog, msg)
    from . import _cache

    # JAX's persistent compilation cache (a second run loads what the first compiled).
    _cache.configure(disabled=args.no_compilation_cache)
    import matplotlib

    # The command line writes PNG files and never shows a window: headless backend, chosen here
    # (the library itself never changes the user's backend).
    matplotlib.use("Agg")
    from .._validation import InputError

    try:
        return _run(args)
    except InputError as exc:  # a value that only the computation could judge (e.g. a Newton step)
        return fail(prog, str(exc).splitlines()[0])


if __name__ == "__main__":
    raise SystemExit(main())
