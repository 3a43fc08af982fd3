"""``jaxtrack design``: sampling schedules for Ho's 1/s² plant (Sec. III-A, III-B and optax designs).

Every subcommand prints the designed schedule and its terminal position variance J = P_T(1,1)
next to the uniform and Ho-rule schedules with the same sample budget, and writes a PNG of the
covariance histories.
"""

from __future__ import annotations

import json

import numpy as np

from ._args import int_in, positive_float


def add_parser(sub) -> None:
    p = sub.add_parser("design", help="design sampling schedules for Ho's plant (uniform Newton, Ho's rule, gradient)")
    p.add_argument("method", choices=["uniform", "ho", "gradient"],
                   help="uniform: Newton for the τ meeting --target; ho: Ho's rule (remove from the least "
                        "sensitive segments); gradient: optax on relaxed counts + rounding + local search, and per-step τ_k")
    p.add_argument("--g", type=positive_float, default=1.0, help="plant-noise level in g, > 0 (default 1)")
    p.add_argument("--samples", type=int_in(5, MAX_SAMPLES), default=40,
                   help=f"sample budget over the 5 s, 5 … {MAX_SAMPLES} (default 40)")
    p.add_argument("--cap-lo", type=int_in(1), default=1, help="fewest samples per 1-s segment (default 1)")
    p.add_argument("--cap-hi", type=int_in(1, MAX_SAMPLES), default=20, help="most samples per 1-s segment (default 20)")
    p.add_argument("--target", type=positive_float, default=1000.0, help="J* in ft² for the uniform design, > 0 (default 1000)")
    p.add_argument("--out", default="results/design", help="folder for the figure")
    p.add_argument("--json", action="store_true", help="print the rows as JSON")


# The gradient design carries cap-hi sample slots per segment and the per-step design one
# parameter per sample through hundreds of Adam steps: beyond a few thousand samples a run takes
# hours and gigabytes, so larger budgets are refused up front.
MAX_SAMPLES = 2000


def check_args(args) -> str | None:
    """The cross-argument check of ``design`` (caps against the budget); the message or None."""
    S, lo, hi = 5, args.cap_lo, args.cap_hi
    if not (lo <= hi and S * lo <= args.samples <= S * hi):
        return (f"need 1 ≤ cap-lo ≤ cap-hi and 5·cap-lo ≤ samples ≤ 5·cap-hi; got samples={args.samples}, "
                f"caps=[{lo}, {hi}]")
    return None


def _ho_counts(problem, samples: int) -> tuple[int, ...]:
    from ..applications import ho_sensitivity as ho
    from ..design import ho_reduction

    start = ho.UNIFORM if samples <= 50 else tuple(int(np.ceil(samples / 5)) for _ in range(5))
    return ho_reduction(problem, start, sum(start) - samples, cap=0.5)


def run(args) -> int:
    import jax.numpy as jnp

    from ..applications import ho_sensitivity as ho
    from ..applications._report import write_figures
    from ..covariance import covariance_recursion
    from ..design import local_search, newton_uniform_period, per_step_design, relaxed_segment_design, round_counts
    from ..models import ho_plant

    S, lo, hi = 5, args.cap_lo, args.cap_hi
    if msg := check_args(args):  # main() checks first; kept for direct callers
        print(f"jaxtrack design: error: {msg}", file=__import__("sys").stderr)
        return 2
    problem = ho.segment_problem(args.g)
    uniform = tuple(round(c) for c in np.diff(np.round(np.linspace(0, args.samples, S + 1))))
    rows = [{"design": "uniform", "schedule": list(uniform), "J": problem.cost(uniform)}]
    if args.samples <= 50:
        ho_counts = _ho_counts(problem, args.samples)
        rows.append({"design": "Ho's rule", "schedule": list(ho_counts), "J": problem.cost(ho_counts)})
    curves = [(r["design"], ho.history(tuple(r["schedule"]), args.g)) for r in rows]

    if args.method == "uniform":
        from .._validation import InputError

        fn = lambda t: ho_plant(jnp.full(args.samples, t), g=args.g)  # noqa: E731
        tau0 = 5.0 / args.samples
        try:
            r = newton_uniform_period(fn, tau0, args.target, ho.POSITION)
        except InputError as exc:
            if "feasible region" not in str(exc):
                raise
            # The library's advice (`step_factor`, `tau0`) names arguments this command does not
            # have: say what the command line can change.
            raise InputError(
                f"--target {args.target:g} ft² is out of reach of Newton's iteration from the uniform period "
                f"τ0 = {tau0:g} s, where J = {rows[0]['J']:.4g} ft² (it stepped to τ ≤ 0). Give a --target nearer "
                "that, or more --samples; from Python, jaxtrack.design.newton_uniform_period takes `tau0` and "
                "`step_factor`."
            ) from None
        rows.append({"design": "Newton uniform τ (III-A)", "schedule": [float(r.taus[-1])] * args.samples,
                     "J": float(r.costs[-1]), "iterates": [float(t) for t in r.taus]})
        hist = covariance_recursion(fn(jnp.asarray(r.taus[-1])))
        curves.append(("Newton", (hist, r.taus[-1] * (1 + np.arange(args.samples)))))
    elif args.method == "gradient":
        relaxed = relaxed_segment_design(problem, args.samples, lo=lo, hi=hi)
        counts, J = local_search(problem, round_counts(relaxed.counts, args.samples, lo, hi), lo=lo, hi=hi)
        rows.append({"design": "gradient (optax, relaxed)", "schedule": [round(float(c), 3) for c in relaxed.counts], "J": relaxed.cost})
        rows.append({"design": "gradient, rounded + local search", "schedule": list(counts), "J": J})
        curves.append(("gradient", ho.history(counts, args.g)))
        ps = per_step_design(lambda t: ho_plant(t, g=args.g), args.samples, 5.0 - 5.0 / args.samples, ho.POSITION,
                             first_time=5.0 / args.samples)
        rows.append({"design": "per-step τ_k (optax)", "schedule": [round(float(t), 4) for t in ps.times], "J": ps.cost})
        curves.append(("per-step τ_k", (covariance_recursion(ho_plant(jnp.asarray(ps.taus), g=args.g)), ps.times)))

    labelled = [(f"{name}: P_T = {float(hist.filtered_cov[-1, 0, 0]):.1f} ft²", hist, times) for name, (hist, times) in curves]
    (figure,) = write_figures(args.out, [(f"design_{args.method}.png", lambda: ho.figure_covariance_histories(
        labelled, f"jaxtrack design {args.method}: {args.g:g} g, {args.samples} samples"))])

    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    print(f"{'design':<34} {'J = P_T(1,1) [ft²]':>20}  schedule")
    for r in rows:
        sched = r["schedule"]
        text = f"τ = {sched[0]:.8f} s × {len(sched)}" if r["design"].startswith("Newton") else (
            f"sample times {sched[:3]} … {sched[-2:]}" if r["design"].startswith("per-step") else str(tuple(sched)))
        print(f"{r['design']:<34} {r['J']:>20.2f}  {text}")
    print(f"figure: {figure}")
    return 0
