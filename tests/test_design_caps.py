"""No hangs in jaxtrack.design: infeasible or non-finite inputs are refused, and every iterative
design is capped and says when it stopped at its cap (issue 24).

Each call runs under a SIGALRM deadline, so a regression fails the test instead of hanging CI."""

import contextlib
import signal
import warnings

import jax.numpy as jnp
import numpy as np
import pytest

from jaxtrack import InputError
from jaxtrack.applications import ho_sensitivity as ho
from jaxtrack.design import (
    NotConvergedWarning,
    exhaustive_counts,
    local_search,
    newton_uniform_period,
    relaxed_segment_design,
    round_counts,
    segment_exchange,
)
from jaxtrack.models import ho_plant

L_POS = jnp.diag(jnp.array([1.0, 0.0]))


class Hang(Exception):
    pass


@contextlib.contextmanager
def deadline(seconds):
    """Raise ``Hang`` in the main thread after ``seconds`` (the loops under test are Python loops)."""

    def on_alarm(signum, frame):
        raise Hang(f"did not return within {seconds} s")

    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


@pytest.mark.parametrize("counts, total, lo, hi, name", [
    ([1.0, 1.0], 100, 1, 5, "total"),  # the example: used to loop forever
    ([1.0, 1.0], 1, 1, 5, "total"),  # below S·lo: the downward loop never ended either
    ([np.nan, 1.0], 4, 1, 5, "counts"),  # NaN count: used to loop forever
    ([np.inf, 1.0], 4, 1, 5, "counts"),
    ([1.0, 1.0], 4, 3, 2, "lo"),
    ([1.0, 1.0], 4.5, 1, 5, "total"),
])
def test_round_counts_refuses_what_it_cannot_meet(counts, total, lo, hi, name):
    with deadline(5), pytest.raises(InputError, match=f"`{name}`"):
        round_counts(counts, total, lo, hi)


def test_round_counts_still_rounds_feasible_totals():
    with deadline(5):
        assert round_counts([1.4, 2.6], 4, 1, 5) == (1, 3)
        assert round_counts([0.2, 0.2, 0.2], 10, 1, 4) == (4, 3, 3)  # every count clipped to lo first
        assert round_counts([9.9, 9.9], 10, 5, 5) == (5, 5)  # total = S·hi exactly
        assert sum(round_counts([7.3, 0.1, 12.6, 3.3, 16.7], 40, 1, 20)) == 40


def test_exhaustive_counts_refuses_an_enumeration_that_would_not_end():
    # (1000 − 1 + 1)^4 = 1e12 candidate vectors: the unchecked itertools.product ran for hours.
    problem = ho.segment_problem(1.0)
    with deadline(5), pytest.raises(InputError, match="max_schemes"):
        exhaustive_counts(problem, 1000, hi=1000)


def test_local_search_and_exchange_warn_at_their_cap():
    problem = ho.segment_problem(1.0)
    with deadline(60):
        with pytest.warns(NotConvergedWarning, match="max_iter"):
            counts, J = local_search(problem, (20, 10, 5, 4, 1), hi=20, max_iter=1)
        assert sum(counts) == 40 and J < problem.cost((20, 10, 5, 4, 1))
        with pytest.warns(NotConvergedWarning, match="max_iter"):
            counts, costs = segment_exchange(problem, (8, 8, 8, 8, 8), max_iter=1)
        assert len(costs) == 2 and costs[1] < costs[0]
        with warnings.catch_warnings():
            warnings.simplefilter("error", NotConvergedWarning)
            local_search(problem, (8, 1, 1, 10, 20), hi=20)  # already the optimum: no warning
        for fn in (local_search, segment_exchange):
            with pytest.raises(InputError, match="`max_iter`"):
                fn(problem, (8, 8, 8, 8, 8), max_iter=0)


def test_newton_reports_non_convergence_and_refuses_non_finite_inputs():
    fn = lambda t: ho_plant(jnp.full(50, t))  # noqa: E731
    with deadline(60):
        r = newton_uniform_period(fn, 0.1, 1000.0, L_POS, max_iter=1)
        assert not r.converged and len(r.taus) == 2
        for kwargs, name in (({"target": np.nan}, "target"), ({"tau0": np.nan}, "tau0"),
                             ({"max_iter": 0}, "max_iter")):
            args = {"tau0": 0.1, "target": 1000.0, **kwargs}
            with pytest.raises(InputError, match=f"`{name}`"):
                newton_uniform_period(fn, args["tau0"], args["target"], L_POS, **{k: v for k, v in kwargs.items()
                                                                                     if k == "max_iter"})


def test_relaxed_design_refuses_bad_steps_and_init():
    problem = ho.segment_problem(1.0)
    with pytest.raises(InputError, match="`steps`"):
        relaxed_segment_design(problem, 40, steps=0)
    with pytest.raises(InputError, match="`init`"):
        relaxed_segment_design(problem, 40, init=[np.nan, 8, 8, 8, 8])
