"""Test configuration: float64, loud numerics, and an opt-in flag for slow Monte Carlo sizes."""

import importlib
import os
from pathlib import Path

# JAX's persistent compilation cache for the suite, set before JAX is imported so that every
# process of the run shares it: both xdist workers, the notebook kernels and the CLI, sharded and
# wheel subprocesses inherit the variables. A program compiled by one of them (or compiled again
# after `jax.clear_caches()` below) is then loaded from disk. The folder is inside the checkout
# (.cache/, gitignored), so a fresh clone starts cold, as CI does; JAXTRACK_TEST_CACHE_DIR=PATH
# puts it elsewhere, JAXTRACK_TEST_CACHE_DIR=off runs without it.
from jaxtrack.cli._cache import OFF_VALUES  # noqa: E402  (jaxtrack imports no JAX)

# Unlike the CLI (every compilation), the suite writes only compilations of at least 0.2 s: a test
# process rarely meets a short program twice after JAX's in-memory cache, and writing all of them
# gave no gain (six modules: 139.9 s against 138.5 s) for 20x the files (987 against 44).
MIN_COMPILE_TIME_S = 0.2

_TEST_CACHE = os.environ.get("JAXTRACK_TEST_CACHE_DIR", str(Path(__file__).resolve().parent.parent / ".cache" / "jax"))
if _TEST_CACHE.strip().lower() in OFF_VALUES:
    os.environ.pop("JAX_COMPILATION_CACHE_DIR", None)
    os.environ["JAXTRACK_CACHE_DIR"] = "off"  # the CLI's own default cache, off as well
else:
    os.environ["JAX_COMPILATION_CACHE_DIR"] = _TEST_CACHE
    os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = str(MIN_COMPILE_TIME_S)
    os.environ["JAXTRACK_CACHE_DIR"] = _TEST_CACHE  # the CLI subprocesses: same folder, not ~/.cache

# XLA compiles the suite's programs with most optimisations off (JAX's
# jax_disable_most_optimizations: LLVM -O0, no expensive LLVM passes), set through the environment
# before JAX is imported so that the xdist workers, notebook kernels and CLI/sharded subprocesses
# inherit it and share the persistent cache. The suite is compile-bound (58% of its
# worker-seconds are XLA compilation, its programs mostly run for milliseconds): -O0 compiles
# about 25% faster and runs about 1.6x slower. Over the whole suite (fresh clone, 2 cores): 2301 ->
# 2163 worker-seconds, .ci/run 21:04 -> 19:57 (measured with XLA_FLAGS'
# --xla_backend_optimization_level=0; this JAX flag compiles the same: test_properties +
# test_faults 104.4 against 104.9 CPU-s, 116.1 at the default level).
# The modules that run long programs lose at -O0 (test_multitarget_learning 77.7 against 50.6 CPU-s);
# they mark themselves ``pytestmark = pytest.mark.xla_optimized`` and run at the default level
# (the fixture below). That is per module in the same session, not a session of its own (which
# lost: 20:35 against 19:57), and a notebook that shares such a module's programs runs its kernel at
# the same level (tests/test_notebooks.py), or the two would no longer share them through the cache
# (the cache key holds the compile options): the multitarget notebook at the default level beside
# its -O0 tests took 58.6 s against 45.3 s.
# JAXTRACK_TEST_XLA_DEFAULT=1 turns all of this off (everything at the default level).
# Both levels compute in IEEE double without fast-math; the rounding of fused multiply-adds may
# differ (1e-16 relative per operation), which only the c1ffaca row baseline, held to 1e-12, sees
# in two ill-conditioned studies (tests/rows_baseline.py states their -O0 tolerances). Users and
# the benchmarks run at XLA's default.
FAST_COMPILE_ENV = "JAX_DISABLE_MOST_OPTIMIZATIONS"
XLA_DEFAULT = os.environ.get("JAXTRACK_TEST_XLA_DEFAULT", "") == "1"
# XLA:CPU's former elemental emitters instead of its fusion emitters (jaxlib 0.10's default, which
# lower every fusion through MLIR before LLVM): the same programs compile in less than half the
# time (tests/test_association_jpda.py + test_filters.py, cold, one process: XLA compile 36 -> 15 s,
# wall 53 -> 32 s). Process-wide (read when XLA's CPU backend starts), so set through the
# environment and inherited like the variable above. The two emitters round differently where a
# fusion's boundaries differ (e.g. 4e-17 absolute in a GM-PHD weight): only the multi-target
# contract's comparison with results computed before its refactor, with the fusion emitters, sees
# that (it holds them bit for bit under JAXTRACK_TEST_FUSION_EMITTERS=1, `make test-slow`, and to
# the last bits otherwise: tests/test_multitarget_contract.py). make test ran the modules held to
# the fusion emitters in a session of its own until that comparison was made emitter-aware and the
# square-root test's random models contracting (their states had grown to 9e18, so its innovations
# compared rounding noise): that session, now at the former emitters, 116 -> 55 s and the contract
# 90 -> 52 s, cold, one process. An XLA without the flag would refuse to start: a jaxlib update
# (make lock) runs the suite first.
LEGACY_EMITTERS_FLAG = "--xla_cpu_use_fusion_emitters=false"
FUSION_EMITTERS = XLA_DEFAULT or os.environ.get("JAXTRACK_TEST_FUSION_EMITTERS", "") == "1"
if not XLA_DEFAULT:
    os.environ[FAST_COMPILE_ENV] = "1"
if not FUSION_EMITTERS and LEGACY_EMITTERS_FLAG not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " " + LEGACY_EMITTERS_FLAG).strip()

import jax
import pytest
from jaxtyping import install_import_hook

# Runtime shape checking: the jaxtyping annotations of the numeric layers (function arguments and
# returns, equinox Module fields) are checked by beartype while the tests run, so the shapes the
# docstrings and annotations promise are the shapes the code produces. Off outside the test suite
# (no cost for users); JAXTRACK_TYPECHECK=0 turns it off here too. The user-facing entry points
# (run_filter, model constructors, monte_carlo, design, the CLI) are left out on purpose: they
# validate their inputs themselves and raise InputError naming the argument, which the tests
# check, and a type checker in front of them would answer first with a different error.
TYPECHECKED = [
    "jaxtrack.filters._updates",
    "jaxtrack.filters._kalman",
    "jaxtrack.filters._unscented",
    "jaxtrack.filters._smoother",
    "jaxtrack.filters._linalg",
    "jaxtrack.filters._consider",
    "jaxtrack.filters._iterated",
    "jaxtrack.filters._square_root",
    "jaxtrack.filters._parallel",
    "jaxtrack.models._motion",
    "jaxtrack.models._sensors",
    "jaxtrack.models._converted",
    "jaxtrack.covariance",
    "jaxtrack.geometry",
    "jaxtrack.estimation",
    "jaxtrack.montecarlo._metrics",
    "jaxtrack.montecarlo._cep",
    "jaxtrack.bounds._pcrlb",
    "jaxtrack.design._observer",
    "jaxtrack.applications.bearings_tma",
    "jaxtrack.applications.ho_sensitivity",
    "jaxtrack.learning._params",
    "jaxtrack.learning._mle",
    "jaxtrack.association._jpda",
    "jaxtrack.association._pda_update",
    "jaxtrack.association._clusters",
    "jaxtrack.association._assignment",
]
if os.environ.get("JAXTRACK_TYPECHECK", "1") != "0":
    with install_import_hook(TYPECHECKED, "beartype.beartype"):
        import jaxtrack  # noqa: F401  (switches on float64)

        # jaxtrack imports its subpackages on first use: import them here, inside the hook, so
        # that the checked modules among them are decorated (a module first imported later is
        # not). These are the subpackages `import jaxtrack` used to import eagerly; the listed
        # modules outside them (applications.*, estimation) were never imported inside the
        # hook, hence never checked — importing them here shows annotation mismatches
        # (e.g. ho_sensitivity.figures' fontsize: float given 7), left for a later change.
        for _name in (f"jaxtrack.{p}" for p in jaxtrack._SUBPACKAGES):
            importlib.import_module(_name)
else:
    import jaxtrack  # noqa: F401

jax.config.update("jax_enable_x64", True)
if "JAX_COMPILATION_CACHE_DIR" in os.environ:  # in case a plugin imported JAX before this file
    jax.config.update("jax_compilation_cache_dir", os.environ["JAX_COMPILATION_CACHE_DIR"])
    jax.config.update("jax_persistent_cache_min_compile_time_secs", MIN_COMPILE_TIME_S)
# Catch accidental rank broadcasting between e.g. (n,) and (n, 1).
jax.config.update("jax_numpy_rank_promotion", "raise")


def pytest_addoption(parser):
    parser.addoption(
        "--runslow",
        action="store_true",
        default=os.environ.get("JAXTRACK_RUNSLOW", "") == "1",
        help="run tests marked slow (large Monte Carlo sizes)",
    )


# Scheduling for `pytest -n 2` (make test): each test module is one work unit of a worker (its
# module fixtures are built once, on one worker), except the notebooks, one unit each; the
# longest units are handed out first (collection order below, kept by --no-loadscope-reorder)
# so that no worker is left alone with a long one at the end: every module of 15 s or more, in
# the order of a profiled run (tools/suite_profile.py), so that each session ends on short
# modules (alphabetical order had put the multi-target modules, 30-50 s each, at the end of the
# first half). A module missing from this list only runs later. Order only, never selection.
# (xdist_group marks cannot do this here: xdist's worker reads them in a collection hook that
# runs before this file's, and then sends every test on its own, so a module fixture was built on
# both workers and torn down between tests.)
_LONG_FIRST = (
    "test_notebooks", "test_multitarget_contract", "test_performance_paths", "test_multitarget_fusion",
    "test_bearings_tma", "test_multitarget_learning", "test_sharding", "test_design", "test_obem_registration",
    "test_particle_filter", "test_maneuvering", "test_properties", "test_sensors",
    "test_multitarget_study", "test_sensitivity", "test_sensor_management", "test_calibration",
    "test_multitarget_no_silent_answers", "test_gibbs", "test_glmb", "test_imm_fit", "test_pmbm",
    "test_imm_smoother", "test_faults", "test_pcrlb", "test_square_root", "test_nonlinear_filters",
    "test_mc_detections", "test_filters", "test_radar_bias", "test_mc_design", "test_ho_study",
    "test_covariance", "test_motion_models", "test_learning_em", "test_imm", "test_core_api",
    "test_reproduce_cli", "test_mc_imm", "test_observer_design", "test_mc_gradient",
    "test_sar_navigation", "test_tma_bounds", "test_gm_phd", "test_multitarget_tracker", "test_figures",
    "test_association_jpda", "test_learning_fit", "test_parallel_kalman", "test_cli",
    "test_iterated_ekf", "test_learning_mle", "test_learning_coverage", "test_models",
    "test_filter_export",
)


def _work_unit(nodeid: str) -> str:
    path, _, rest = nodeid.partition("::")
    if path.endswith("test_notebooks.py") and "[" in rest:
        return nodeid
    return path


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    from xdist.scheduler import LoadScopeScheduling

    class ModuleUnits(LoadScopeScheduling):
        def _split_scope(self, nodeid):
            return _work_unit(nodeid)

    return ModuleUnits(config, log)


def pytest_collection_modifyitems(config, items):
    rank = {name: i for i, name in enumerate(_LONG_FIRST)}
    order = {}
    for i, item in enumerate(items):
        order.setdefault(_work_unit(item.nodeid), i)
    # Stable: units keep their own test order; long units first, then collection order.
    items.sort(key=lambda it: (rank.get(it.path.stem, len(rank)), order[_work_unit(it.nodeid)]))
    if config.getoption("--runslow"):
        return
    skip = pytest.mark.skip(reason="slow: run with --runslow or JAXTRACK_RUNSLOW=1")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)


def fast_compile() -> bool:
    """Whether this process compiles now with most optimisations off (the suite's default)."""
    return bool(jax.config.read("jax_disable_most_optimizations"))


@pytest.fixture(autouse=True, scope="module")
def _optimisation_level(request):
    """A module marked ``xla_optimized`` runs at XLA's default level (see the top of this file)."""
    if XLA_DEFAULT or request.node.get_closest_marker("xla_optimized") is None:
        yield
        return
    jax.config.update("jax_disable_most_optimizations", False)
    try:
        yield
    finally:
        jax.config.update("jax_disable_most_optimizations", True)


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_code():
    """Drop JAX's compilation caches after each test module.

    The suite compiles thousands of programs; XLA's CPU compiler has crashed (SIGSEGV in
    ``backend_compile``) late in long processes holding all of them. No test relies on a
    compilation made by another module, so releasing them costs only recompiling shared helpers.
    """
    yield
    jax.clear_caches()


# Where the suite's time goes: JAXTRACK_TEST_PROFILE=FOLDER writes one line per test to
# FOLDER/<pid>.tsv (one file per process): its wall time, the seconds JAX spent in XLA's compiler
# and in tracing/lowering during it (module fixtures count in the first test that builds them),
# and the process's resident memory after it (MB). tools/suite_profile.py sums them by module.
# Off by default: no listener is registered.
_PROFILE_DIR = os.environ.get("JAXTRACK_TEST_PROFILE")
if _PROFILE_DIR:
    import time as _time

    _totals = {"compile": 0.0, "trace": 0.0}
    _TRACE_EVENTS = ("/jax/core/compile/jaxpr_trace_duration", "/jax/core/compile/jaxpr_to_mlir_module_duration")

    def _listen(event, duration, **_):
        if event == "/jax/core/compile/backend_compile_duration":
            _totals["compile"] += duration
        elif event in _TRACE_EVENTS:
            _totals["trace"] += duration

    jax.monitoring.register_event_duration_secs_listener(_listen)

    # Programs JAX compiles but will not write to the persistent cache because they hold a host
    # callback (an `equinox.error_if`, a `jax.debug` call): every process, and every test after
    # `jax.clear_caches()`, compiles them again. Recorded per test in FOLDER/<pid>.uncached.tsv
    # (test, program name, its compile seconds); tools/suite_profile.py sums them by program.
    from jax._src import compiler as _compiler

    _cache_write = _compiler._cache_write
    _uncached: list = []

    def _recording_cache_write(cache_key, compile_time_secs, module_name, backend, executable, host_callbacks):
        if host_callbacks:
            _uncached.append((module_name, compile_time_secs))
        return _cache_write(cache_key, compile_time_secs, module_name, backend, executable, host_callbacks)

    _compiler._cache_write = _recording_cache_write

    def _rss_mb() -> float:
        with open("/proc/self/statm", encoding="ascii") as f:  # Linux: resident pages, 2nd field
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_protocol(item, nextitem):
        before, t = dict(_totals), _time.perf_counter()
        yield
        wall = _time.perf_counter() - t
        Path(_PROFILE_DIR).mkdir(parents=True, exist_ok=True)
        with open(Path(_PROFILE_DIR) / f"{os.getpid()}.tsv", "a", encoding="utf-8") as f:
            f.write(f"{item.nodeid}\t{wall:.3f}\t{_totals['compile'] - before['compile']:.3f}"
                    f"\t{_totals['trace'] - before['trace']:.3f}\t{_rss_mb():.0f}\n")
        if _uncached:
            with open(Path(_PROFILE_DIR) / f"{os.getpid()}.uncached.tsv", "a", encoding="utf-8") as f:
                f.writelines(f"{item.nodeid}\t{name}\t{secs:.3f}\n" for name, secs in _uncached)
            _uncached.clear()
