"""What a Monte Carlo run returns: the streamed per-step sums and their summary statistics.

:class:`_Sums` is what every block of runs adds to (per-step sums over runs, nothing per run);
:func:`_summarize` turns the totals into a :class:`MonteCarloResult` with χ² bounds
(:func:`~jaxtrack.montecarlo.chi2_mean_bounds`).
"""

from __future__ import annotations

import dataclasses
import json
import os
import uuid
import warnings
import zipfile
import zlib
from pathlib import Path
from typing import Literal, NamedTuple

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._validation import InputError
from ._metrics import chi2_mean_bounds

# Version of the ``save``/``to_dict`` layout; ``load`` refuses any other. Raise it when a field
# changes meaning, not when one is added with a default (older files then still load).
EXPORT_FORMAT_VERSION = 1
_EXPORT_KIND = "jaxtrack.MonteCarloResult"


class _Sums(NamedTuple):
    """Per-step sums over the runs seen so far (all float64 under the default precision)."""

    error: Array  # (T, n): Σ (x − x̂)
    squared_error: Array  # (T, n): Σ (x − x̂)²
    nees: Array  # (T,): Σ NEES
    nees_sq: Array  # (T,): Σ NEES², for the empirical spread
    nis: Array  # (T,): Σ NIS
    num_ok: Array  # (): runs that stayed finite
    num_failed: Array  # (): runs that produced a non-finite value (excluded from the sums)
    nis_dof: Array  # (T,): Σ observed measurement components (NIS degrees of freedom) over the runs
    mode_probs: Array  # (T, K): Σ mode probabilities (an IMM's K modes; K = 0 for one filter)


class MonteCarloResult(eqx.Module):
    """Statistics of a Monte Carlo run of ``num_runs`` runs over ``T`` steps.

    **Fields:**

    - ``mse`` ``(T, n)``: mean squared error of each state component at each step.
    - ``mean_error`` ``(T, n)``: mean of ``x − x̂`` (the bias; 0 for a linear filter).
    - ``nees`` ``(T,)``: NEES averaged over runs; ``nees_bounds`` ``(T, 2)`` its two-sided bounds.
    - ``nees_std`` ``(T,)``: the empirical standard deviation of NEES over runs.
    - ``nis`` ``(T,)``: NIS averaged over runs; ``nis_dof`` ``(T,)`` its degrees of freedom (the
      measurement components observed, averaged over the runs: with per-run detections or
      masks, a run's NIS at step ``k`` is χ²(d_ik) with ``d_ik`` its own observed components);
      ``nis_bounds`` ``(T, 2)``: the bounds of the run average, from χ²(Σ_i d_ik) / M (a sum of
      independent χ²(d_i) is χ²(Σ d_i)); ``[0, 0]`` at steps no run observed.
    - ``anees`` ``()``: NEES averaged over runs and steps and divided by ``n`` (1 when
      consistent). ``anees_bounds`` ``(2,)``: the per-step χ²(M·n)/(M·n) bounds. Averaging over
      steps cannot increase the variance of the per-step average (steps are positively
      correlated at worst completely), so these bounds are valid and conservative for ``anees``.
    - ``num_runs``: runs that contributed; ``num_failed``: runs excluded because the filter
      produced a non-finite value (a warning is issued when this is not 0).
    - ``confidence``: the probability content of the bounds (default 0.95).
    - ``shared_covariance``: True when the filter's covariances were computed once for all runs
      (see :func:`monte_carlo`), False when every run carried its own.
    - ``precision_warning``: True when the statistics were accumulated in a floating type
      narrower than float64 and the ANEES or the mean NIS exceed ``PRECISION_MARGIN`` (10) times
      their upper bounds (a ``RuntimeWarning`` naming float32 is issued too). A mismodelled
      filter rarely exceeds its bound by more than a few times; float32 round-off of a
      near-singular covariance (long runs, tiny process noise, large states) gives 10²–10⁵.
      Float64 results never set it: there such a ratio is a modelling error, not round-off.
    - ``mode_probs`` ``(T, K)``: for an :class:`~jaxtrack.filters.InteractingMultipleModel`
      filter, its ``K`` mode probabilities ``μ_j(k)`` averaged over runs; None for one filter.
    - ``components``: the filter state components scored (``filter_components`` of
      :func:`monte_carlo`), in the order of ``mse``'s columns; None when the whole state is.

    **Export:** :meth:`to_dict` (NumPy arrays or JSON-ready lists), :meth:`save` to one ``.npz``
    and :meth:`load` back, bit for bit; both carry ``format_version`` (1).
    """

    mse: Float[Array, "T n"]
    mean_error: Float[Array, "T n"]
    nees: Float[Array, " T"]
    nees_std: Float[Array, " T"]
    nees_bounds: Float[Array, "T 2"]
    nis: Float[Array, " T"]
    nis_dof: Float[Array, " T"]
    nis_bounds: Float[Array, "T 2"]
    anees: Float[Array, ""]
    anees_bounds: Float[Array, " 2"]
    num_runs: int = eqx.field(static=True)
    num_failed: int = eqx.field(static=True)
    confidence: float = eqx.field(static=True)
    shared_covariance: bool = eqx.field(static=True, default=False)
    precision_warning: bool = eqx.field(static=True, default=False)
    mode_probs: Float[Array, "T K"] | None = None
    components: tuple[int, ...] | None = eqx.field(static=True, default=None)

    def rmse(self, components: tuple[int, ...] | None = None) -> Float[Array, " T"]:
        """Root of the summed mean squared error over ``components`` (all states if None).

        For a 2-D constant-velocity state ``[x, y, vx, vy]``, ``rmse((0, 1))`` is the position RMSE.
        ``components`` index the columns of ``mse`` (the scored components, in their order).
        """
        mse = self.mse if components is None else self.mse[:, jnp.asarray(components)]
        return jnp.sqrt(jnp.sum(mse, axis=-1))

    def fraction_nees_inside(self) -> Float[Array, ""]:
        """Fraction of steps whose run-averaged NEES lies within its bounds (≈ confidence)."""
        inside = (self.nees >= self.nees_bounds[:, 0]) & (self.nees <= self.nees_bounds[:, 1])
        return jnp.mean(inside)

    # ---- export -----------------------------------------------------------------------------
    # The array fields (leaves) and the static fields (metadata) are found from the dataclass
    # fields, so a field added later is exported without touching these methods.

    @classmethod
    def _split_fields(cls) -> tuple[list[dataclasses.Field], list[dataclasses.Field]]:
        fields = dataclasses.fields(cls)
        static = [f for f in fields if f.metadata.get("static", False)]
        arrays = [f for f in fields if not f.metadata.get("static", False)]
        return arrays, static

    def _meta(self) -> dict:
        """The static fields as JSON-ready Python values, plus ``format_version`` and ``kind``."""
        _, static = self._split_fields()
        meta = {"format_version": EXPORT_FORMAT_VERSION, "kind": _EXPORT_KIND}
        for f in static:
            value = getattr(self, f.name)
            # numpy scalars (np.int64 component indices, an np.float32 confidence) → Python ones
            if isinstance(value, (tuple, list)):
                value = [v.item() if isinstance(v, np.generic) else v for v in value]
            elif isinstance(value, np.generic):
                value = value.item()
            meta[f.name] = value
        return meta

    def to_dict(self, arrays: Literal["numpy", "list"] = "numpy") -> dict:
        """Everything in the result as a plain dict: per-step curves and metadata.

        **Arguments:**

        - ``arrays``: ``"numpy"`` (default) gives each array field as a NumPy array of its own
          dtype and shape; ``"list"`` gives nested Python lists / floats (``ndarray.tolist()``),
          so that ``json.dumps(result.to_dict("list"))`` works (float64 values round-trip
          exactly through JSON's shortest repr; the dtype itself is not kept in that form).

        **Returns:** a dict with

        - the array fields, with their shapes (``T`` steps, ``n`` scored components, ``K``
          modes; units are those of the state, squared for ``mse``): ``mse`` ``(T, n)``,
          ``mean_error`` ``(T, n)``, ``nees`` / ``nees_std`` ``(T,)``, ``nees_bounds`` ``(T, 2)``,
          ``nis`` / ``nis_dof`` ``(T,)``, ``nis_bounds`` ``(T, 2)``, ``anees`` ``()``,
          ``anees_bounds`` ``(2,)``, ``mode_probs`` ``(T, K)`` or None (a single filter);
          a result of :func:`monte_carlo_sweep` element has the same shapes;
        - the metadata: ``num_runs``, ``num_failed``, ``confidence``, ``shared_covariance``,
          ``precision_warning``, ``components`` (a list, or None), and ``format_version`` (1)
          and ``kind`` (``"jaxtrack.MonteCarloResult"``) describing the layout.
        """
        if arrays not in ("numpy", "list"):
            raise InputError(f'`arrays` must be "numpy" or "list"; got {arrays!r}.')
        out = self._meta()
        array_fields, _ = self._split_fields()
        for f in array_fields:
            value = getattr(self, f.name)
            if value is not None:
                value = np.asarray(value)
                if arrays == "list":
                    value = value.tolist()
            out[f.name] = value
        return out

    def save(self, path: str | os.PathLike) -> Path:
        """Write the result to one ``.npz`` file, exactly (bit for bit) restorable by :meth:`load`.

        The file holds one array per array field, under the field's name (fields that are None,
        e.g. ``mode_probs`` of a single filter, are left out), and an entry ``meta``: a JSON
        string of the static fields with ``format_version`` and ``kind`` (see :meth:`to_dict`).
        It is an ordinary ``np.savez`` archive (no pickled objects): ``np.load(path)`` reads it
        without jaxtrack, e.g. ``json.loads(str(np.load(path)["meta"]))``.

        **Arguments:**

        - ``path``: the file to write, used as given (no ``.npz`` is appended). Written to a
          temporary file in the same folder and renamed, so an interrupted save leaves no
          partial file and an existing file is replaced whole.

        **Returns:** ``path`` as a :class:`pathlib.Path`.
        """
        path = Path(path)
        entries = {"meta": np.asarray(json.dumps(self._meta()))}
        array_fields, _ = self._split_fields()
        for f in array_fields:
            value = getattr(self, f.name)
            if value is not None:
                entries[f.name] = np.asarray(value)
        # A new name beside the target ("x" mode: never clobbers), created with the umask's
        # permissions like any written file (mkstemp would make it private, 0600).
        tmp = path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp")
        try:
            with open(tmp, "xb") as fh:
                np.savez(fh, **entries)
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        return path

    @classmethod
    def load(cls, path: str | os.PathLike) -> MonteCarloResult:
        """Read a result written by :meth:`save`.

        **Arguments:**

        - ``path``: a file written by :meth:`MonteCarloResult.save`.

        **Returns:** the :class:`MonteCarloResult`, every array a ``jax.Array`` with the dtype
        and values saved (bit for bit; a float64 file read with float64 disabled in JAX is
        narrowed by JAX to float32), the static fields equal to the saved ones.

        **Raises:** ``FileNotFoundError`` if ``path`` does not exist; :class:`~jaxtrack.InputError`
        naming ``path`` if it is not such a file: not an ``.npz`` archive, no ``meta`` entry,
        another ``kind``, a ``format_version`` other than 1, or missing / unknown fields.
        """
        def bad(why: str) -> InputError:
            return InputError(f"`path` {str(path)!r} is not a saved MonteCarloResult: {why}.")

        read_errors = (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error)
        # Open the file here (FileNotFoundError propagates): np.load given a path leaves its
        # handle open when the archive turns out to be broken.
        with open(path, "rb") as fh:
            try:
                npz = np.load(fh, allow_pickle=False)
            except read_errors as exc:  # not an npz/npy at all, or a pickle we refuse to run
                raise bad(f"cannot be read as an .npz archive ({exc})") from None
            if not isinstance(npz, np.lib.npyio.NpzFile):  # a bare .npy array
                raise bad("it holds one array, not an .npz archive")
            with npz:
                try:
                    entries = {name: npz[name] for name in npz.files}
                except read_errors as exc:
                    raise bad(f"an entry cannot be read ({exc})") from None
        if "meta" not in entries:
            raise bad("it has no `meta` entry")
        try:
            meta = json.loads(str(entries.pop("meta")))
        except ValueError:
            raise bad("its `meta` entry is not JSON") from None
        if not isinstance(meta, dict) or meta.get("kind") != _EXPORT_KIND:
            raise bad(f"`meta.kind` is {meta.get('kind') if isinstance(meta, dict) else None!r}, "
                      f"expected {_EXPORT_KIND!r}")
        version = meta.pop("format_version", None)
        if version != EXPORT_FORMAT_VERSION:
            raise bad(f"format_version {version!r}; this jaxtrack reads format_version {EXPORT_FORMAT_VERSION}")
        meta.pop("kind")
        array_fields, static_fields = cls._split_fields()
        known_arrays = {f.name for f in array_fields}
        known_static = {f.name for f in static_fields}
        if unknown := sorted(set(entries) - known_arrays) + sorted(set(meta) - known_static):
            raise bad(f"unknown fields {unknown}")
        kwargs = {}
        for f in array_fields:
            if f.name in entries:
                kwargs[f.name] = jnp.asarray(entries[f.name])
            elif f.default is dataclasses.MISSING:  # a required array is absent (None ones are left out)
                raise bad(f"the array `{f.name}` is missing")
        for f in static_fields:
            if f.name in meta:
                value = meta[f.name]
                kwargs[f.name] = tuple(value) if isinstance(value, list) else value  # JSON has no tuples
            elif f.default is dataclasses.MISSING:
                raise bad(f"`meta.{f.name}` is missing")
        return cls(**kwargs)


def _zero_sums(num_steps, n, dtype, lead=(), num_modes=0):
    z = lambda *shape: jnp.zeros(lead + shape, dtype)  # noqa: E731
    return _Sums(z(num_steps, n), z(num_steps, n), z(num_steps), z(num_steps), z(num_steps), z(), z(), z(num_steps),
                 z(num_steps, num_modes))




# How far above their upper bounds the ANEES or mean NIS of a reduced-precision Monte Carlo must be
# before the result is flagged as a likely float32 failure (see MonteCarloResult.precision_warning).
PRECISION_MARGIN = 10.0


def _precision_suspect(dtype, anees, anees_hi, nis, nis_hi) -> bool:
    """True when a < float64 result's ANEES or mean NIS is above PRECISION_MARGIN × its bound."""
    if np.dtype(dtype).itemsize >= 8:
        return False
    mean_nis, mean_nis_hi = float(np.mean(nis)), float(np.mean(nis_hi))
    return bool(float(anees) > PRECISION_MARGIN * float(anees_hi)
                or (mean_nis_hi > 0 and mean_nis > PRECISION_MARGIN * mean_nis_hi))


def _summarize(sums: _Sums, n, confidence, shared=False, components=None) -> MonteCarloResult:
    num_ok = int(sums.num_ok)
    num_failed = int(sums.num_failed)
    if num_failed:
        warnings.warn(
            f"jaxtrack.monte_carlo: {num_failed} of {num_ok + num_failed} runs produced a "
            f"non-finite estimate and were left out of the statistics.",
            RuntimeWarning,
            stacklevel=3,
        )
    if num_ok == 0:
        raise FloatingPointError("jaxtrack.monte_carlo: every run produced a non-finite estimate.")
    mean_nees = sums.nees / num_ok
    nees_var = jnp.maximum(sums.nees_sq / num_ok - mean_nees**2, 0.0)
    # Run i's NIS at step k is χ²(d_ik) (its observed components); the runs are independent, so
    # the sum over runs is χ²(D_k), D_k = Σ_i d_ik, and the run average lies in
    # [χ²_{D_k}⁻¹(α/2), χ²_{D_k}⁻¹(1 − α/2)] / M: chi2_mean_bounds of D_k for one "run", over M.
    # With one schedule for all runs D_k = M·d_k and this is chi2_mean_bounds(d_k, M) exactly.
    nis_dof = sums.nis_dof / num_ok
    nees_b = chi2_mean_bounds(np.full(mean_nees.shape, n), num_ok, confidence)
    nis_b = chi2_mean_bounds(np.asarray(sums.nis_dof), 1, confidence) / num_ok
    anees = jnp.mean(mean_nees) / n
    suspect = _precision_suspect(sums.nees.dtype, anees, nees_b[0][1] / n, sums.nis / num_ok, nis_b[:, 1])
    if suspect:
        warnings.warn(
            f"jaxtrack.monte_carlo: ANEES {float(anees):.3g} (upper bound {float(nees_b[0][1] / n):.3g}) or mean "
            f"NIS far outside their bounds in {np.dtype(sums.nees.dtype).name}: float32 round-off in the "
            "covariances is a likely cause; rerun in float64 (unset JAXTRACK_ENABLE_X64) to tell it from "
            "a mismodelled filter.",
            RuntimeWarning,
            stacklevel=3,
        )
    return MonteCarloResult(
        mse=sums.squared_error / num_ok,
        mean_error=sums.error / num_ok,
        nees=mean_nees,
        nees_std=jnp.sqrt(nees_var * num_ok / max(num_ok - 1, 1)),
        nees_bounds=jnp.asarray(nees_b),
        nis=sums.nis / num_ok,
        nis_dof=nis_dof,
        nis_bounds=jnp.asarray(nis_b),
        anees=anees,
        anees_bounds=jnp.asarray(nees_b[0] / n),
        num_runs=num_ok,
        num_failed=num_failed,
        confidence=confidence,
        shared_covariance=shared,
        precision_warning=suspect,
        mode_probs=sums.mode_probs / num_ok if sums.mode_probs.shape[-1] else None,
        components=components,
    )
