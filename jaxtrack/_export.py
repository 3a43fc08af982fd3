"""Export of result objects: ``to_dict``, ``save``/``load`` (one ``.npz``), ``to_xarray``, ``to_pandas``.

One implementation for every result class (:class:`~jaxtrack.montecarlo.MonteCarloResult`,
:class:`~jaxtrack.filters.FilterResult`, :class:`~jaxtrack.filters.SmootherResult`,
:class:`~jaxtrack.filters.IMMResult`): the array fields (pytree leaves) and the static fields
(metadata) are read off the dataclass fields, so a field added later is exported without touching
this module. A result class mixes in :class:`Exportable` and names

- ``_export_kind``: the ``kind`` written to files (``"jaxtrack.FilterResult"``);
- ``_export_dims``: for each array field, the names of its trailing axes (``("time", "state")``);
  leading axes beyond those (a ``vmap``-ed batch of results) are named ``batch_0``, ``batch_1``…;
- ``_export_units``: for each array field, its units, in words (the library does not know a
  state's physical units, so these say e.g. "state units²" for a mean squared error).

Why one ``.npz`` and not pickle: it is an ordinary archive that ``np.load`` reads without
jaxtrack and without running code (``allow_pickle=False``), and it keeps every dtype and bit.
"""

from __future__ import annotations

import dataclasses
import json
import os
import uuid
import zipfile
import zlib
from pathlib import Path
from typing import Any, ClassVar, Literal

import numpy as np

from ._validation import InputError

# Version of the ``save``/``to_dict`` layout; ``load`` refuses any other. Raise it when a field
# changes meaning, not when one is added with a default (older files then still load).
EXPORT_FORMAT_VERSION = 1

_KINDS: dict[str, type] = {}  # kind → class, for nested results (a SmootherResult's `filtered`)
_READ_ERRORS = (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error)


def _plain(value):
    """Static field value → JSON-ready Python value (numpy scalars → Python ones, tuples → lists)."""
    if isinstance(value, (tuple, list)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def _is_array(value) -> bool:
    return hasattr(value, "shape") and hasattr(value, "dtype")


def _as_numpy(value) -> np.ndarray:
    import jax

    # A typed PRNG key array cannot be converted directly; its raw words can.
    if _is_array(value) and jax.dtypes.issubdtype(value.dtype, jax.dtypes.prng_key):
        return np.asarray(jax.random.key_data(value))
    return np.asarray(value)


class Exportable:
    """Mixin giving a result class ``to_dict``, ``save``, ``load``, ``to_xarray`` and ``to_pandas``."""

    _export_kind: ClassVar[str] = ""
    _export_dims: ClassVar[dict[str, tuple[str, ...]]] = {}
    _export_units: ClassVar[dict[str, str]] = {}
    # Old field name -> new, for files saved before a field was renamed (read under the new name).
    _export_renamed: ClassVar[dict[str, str]] = {}

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if cls.__dict__.get("_export_kind"):
            _KINDS[cls._export_kind] = cls

    # ---- flattening --------------------------------------------------------------------------

    @classmethod
    def _split_fields(cls) -> tuple[list[dataclasses.Field], list[dataclasses.Field]]:
        fields = dataclasses.fields(cls)
        static = [f for f in fields if f.metadata.get("static", False)]
        arrays = [f for f in fields if not f.metadata.get("static", False)]
        return arrays, static

    def _meta(self) -> dict:
        """The static fields as JSON-ready values, plus ``format_version`` and ``kind``; nested
        results and tuples of arrays are described under ``nested`` and ``tuples``."""
        _, static = self._split_fields()
        meta: dict[str, Any] = {"format_version": EXPORT_FORMAT_VERSION, "kind": self._export_kind}
        for f in static:
            meta[f.name] = _plain(getattr(self, f.name))
        nested, tuples = {}, {}
        for name, value in self._array_items():
            if isinstance(value, Exportable):
                nested[name] = value._meta()
            elif isinstance(value, (tuple, list)):
                tuples[name] = len(value)
        if nested:
            meta["nested"] = nested
        if tuples:
            meta["tuples"] = tuples
        return meta

    def _array_items(self):
        arrays, _ = self._split_fields()
        for f in arrays:
            value = getattr(self, f.name)
            if value is not None:
                yield f.name, value

    def _flat_arrays(self, prefix: str = "") -> dict[str, np.ndarray]:
        """Every array leaf as NumPy, keyed ``name``, ``name.i`` (tuples) or ``outer/name`` (nested)."""
        out = {}
        for name, value in self._array_items():
            if isinstance(value, Exportable):
                out.update(value._flat_arrays(f"{prefix}{name}/"))
            elif isinstance(value, (tuple, list)):
                for i, v in enumerate(value):
                    out[f"{prefix}{name}.{i}"] = _as_numpy(v)
            else:
                out[f"{prefix}{name}"] = _as_numpy(value)
        return out

    # ---- public API --------------------------------------------------------------------------

    def to_dict(self, arrays: Literal["numpy", "list"] = "numpy") -> dict:
        """Everything in the result as a plain dict: its arrays (per-step curves, histories) and
        its metadata.

        **Arguments:**

        - ``arrays``: ``"numpy"`` (default) gives each array field as a NumPy array of its own
          dtype and shape; ``"list"`` gives nested Python lists (``ndarray.tolist()``), so that
          ``json.dumps(result.to_dict("list"))`` works (float64 values round-trip exactly through
          JSON's shortest repr; the dtype itself is not kept in that form).

        **Returns:** a dict with one entry per array field (a nested result, e.g. a smoother's
        ``filtered``, as a nested dict; a tuple of arrays, e.g. an IMM's ``member_means``, as a
        list), every static field, ``format_version`` (1) and ``kind`` (e.g.
        ``"jaxtrack.FilterResult"``) describing the layout. Fields that are None are None.
        """
        if arrays not in ("numpy", "list"):
            raise InputError(f'`arrays` must be "numpy" or "list"; got {arrays!r}.')

        def conv(value):
            value = _as_numpy(value)
            return value.tolist() if arrays == "list" else value

        out = {k: v for k, v in self._meta().items() if k not in ("nested", "tuples")}
        array_fields, _ = self._split_fields()
        for f in array_fields:
            value = getattr(self, f.name)
            if isinstance(value, Exportable):
                value = value.to_dict(arrays)
            elif isinstance(value, (tuple, list)):
                value = [conv(v) for v in value]
            elif value is not None:
                value = conv(value)
            out[f.name] = value
        return out

    def save(self, path: str | os.PathLike) -> Path:
        """Write the result to one ``.npz`` file, exactly (bit for bit) restorable by :meth:`load`.

        The file holds one array per array field under the field's name (``name.0``, ``name.1``…
        for a tuple of arrays, ``outer/name`` for a nested result; fields that are None are left
        out) and an entry ``meta``: a JSON string of the static fields with ``format_version`` and
        ``kind``. It is an ordinary ``np.savez`` archive (no pickled objects): ``np.load(path)``
        reads it without jaxtrack, e.g. ``json.loads(str(np.load(path)["meta"]))``.

        **Arguments:**

        - ``path``: the file to write, used as given (no ``.npz`` is appended). Written to a
          temporary file in the same folder and renamed, so an interrupted save leaves no partial
          file and an existing file is replaced whole.

        **Returns:** ``path`` as a :class:`pathlib.Path`.
        """
        path = Path(path)
        entries = {"meta": np.asarray(json.dumps(self._meta())), **self._flat_arrays()}
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
    def load(cls, path: str | os.PathLike):
        """Read a result written by :meth:`save` of this class.

        **Arguments:**

        - ``path``: a file written by ``save`` of the same result class.

        **Returns:** the result, every array a ``jax.Array`` with the dtype and values saved (bit
        for bit; a float64 file read with float64 disabled in JAX is narrowed by JAX to float32),
        the static fields equal to the saved ones.

        **Raises:** ``FileNotFoundError`` if ``path`` does not exist; :class:`~jaxtrack.InputError`
        naming ``path`` if it is not such a file: not an ``.npz`` archive, no ``meta`` entry,
        another ``kind``, a ``format_version`` other than 1, missing / unknown fields, or arrays
        that disagree on the length of a named axis (e.g. per-step arrays of different lengths).
        """
        def bad(why: str) -> InputError:
            return InputError(f"`path` {str(path)!r} is not a saved {cls.__name__}: {why}.")

        # Open the file here (FileNotFoundError propagates): np.load given a path leaves its
        # handle open when the archive turns out to be broken.
        with open(path, "rb") as fh:
            try:
                npz = np.load(fh, allow_pickle=False)
            except _READ_ERRORS as exc:  # not an npz/npy at all, or a pickle we refuse to run
                raise bad(f"cannot be read as an .npz archive ({exc})") from None
            if not isinstance(npz, np.lib.npyio.NpzFile):  # a bare .npy array
                raise bad("it holds one array, not an .npz archive")
            with npz:
                try:
                    entries = {name: npz[name] for name in npz.files}
                except _READ_ERRORS as exc:
                    raise bad(f"an entry cannot be read ({exc})") from None
        if "meta" not in entries:
            raise bad("it has no `meta` entry")
        try:
            meta = json.loads(str(entries.pop("meta")))
        except ValueError:
            raise bad("its `meta` entry is not JSON") from None
        if not isinstance(meta, dict) or meta.get("kind") != cls._export_kind:
            raise bad(f"`meta.kind` is {meta.get('kind') if isinstance(meta, dict) else None!r}, "
                      f"expected {cls._export_kind!r}")
        version = meta.get("format_version")
        if version != EXPORT_FORMAT_VERSION:
            raise bad(f"format_version {version!r}; this jaxtrack reads format_version {EXPORT_FORMAT_VERSION}")
        result, used = cls._from_flat(meta, entries, "", bad)
        if unknown := sorted(set(entries) - used):
            raise bad(f"unknown fields {unknown}")
        result._check_dims(bad)
        return result

    def _check_dims(self, bad) -> None:
        """Every named axis (``time``, ``state``, ``mode``…) has one length across the arrays.

        A result built by jaxtrack always has; a file edited or assembled by hand may not (one
        per-step array longer than the others), and would otherwise load and plot misaligned.
        """
        sizes: dict[str, tuple[int, str]] = {}
        for name, arr, dims, _ in self._labelled():
            for axis, dim in zip(dims, arr.shape[len(arr.shape) - len(dims):]):
                first = sizes.setdefault(axis, (dim, name))
                if first[0] != dim:
                    raise bad(f"its arrays disagree on the length of axis `{axis}`: `{first[1]}` has "
                              f"{first[0]}, `{name}` has {dim}")

    @classmethod
    def _from_flat(cls, meta: dict, entries: dict, prefix: str, bad):
        import jax.numpy as jnp

        meta = dict(meta)
        meta.pop("format_version", None)
        meta.pop("kind", None)
        nested = meta.pop("nested", {})
        tuples = meta.pop("tuples", {})
        array_fields, static_fields = cls._split_fields()
        known = {f.name for f in array_fields} | {f.name for f in static_fields}
        if unknown := sorted(set(meta) - known) + sorted((set(nested) | set(tuples)) - known):
            raise bad(f"unknown fields {unknown}")
        kwargs, used = {}, set()
        for old_name, new_name in cls._export_renamed.items():  # a file saved before the rename
            if f"{prefix}{old_name}" in entries and f"{prefix}{new_name}" not in entries:
                entries[f"{prefix}{new_name}"] = entries.pop(f"{prefix}{old_name}")
        for f in array_fields:
            key = f"{prefix}{f.name}"
            if f.name in nested:
                sub = _KINDS.get(nested[f.name].get("kind"))
                if sub is None:
                    raise bad(f"`{key}` has unknown kind {nested[f.name].get('kind')!r}")
                kwargs[f.name], sub_used = sub._from_flat(nested[f.name], entries, f"{key}/", bad)
                used |= sub_used
            elif f.name in tuples:
                names = [f"{key}.{i}" for i in range(int(tuples[f.name]))]
                if missing := [n for n in names if n not in entries]:
                    raise bad(f"the arrays {missing} are missing")
                kwargs[f.name] = tuple(jnp.asarray(entries[n]) for n in names)
                used |= set(names)
            elif key in entries:
                kwargs[f.name] = jnp.asarray(entries[key])
                used.add(key)
            elif f.default is dataclasses.MISSING:
                # A field without a default may still be None (a FilterResult saved with
                # save="final" has no histories): absent means None then, as written.
                if not _optional(f):
                    raise bad(f"the array `{key}` is missing")
                kwargs[f.name] = None
        for f in static_fields:
            if f.name in meta:
                value = meta[f.name]
                kwargs[f.name] = tuple(value) if isinstance(value, list) else value  # JSON has no tuples
            elif f.default is dataclasses.MISSING:
                raise bad(f"`meta.{f.name}` is missing")
        return cls(**kwargs), used

    # ---- labelled exports (optional packages) ------------------------------------------------

    def _labelled(self):
        """``[(name, numpy array, dims, units)]`` for every array leaf (nested ones prefixed)."""
        out = []

        def walk(obj, prefix):
            for name, value in obj._array_items():
                if isinstance(value, Exportable):
                    walk(value, f"{prefix}{name}/")
                    continue
                is_tuple = isinstance(value, (tuple, list))
                items = [(f"{name}.{i}", i, v) for i, v in enumerate(value)] if is_tuple else [(name, None, value)]
                base = obj._export_dims.get(name)
                for label, i, v in items:
                    arr = _as_numpy(v)
                    dims = _dims_for(arr.ndim, base, label)
                    if i is not None:  # members of a tuple may differ in size (IMM members' states)
                        dims = tuple(d if d == "time" or d.startswith("batch_") else f"{d}_{i}" for d in dims)
                    out.append((f"{prefix}{label}", arr, dims, obj._export_units.get(name, "")))

        walk(self, "")
        return out

    def _attrs(self) -> dict:
        """Metadata for xarray/pandas ``attrs``: the static fields (None dropped, lists kept)."""
        meta = {k: v for k, v in self._meta().items() if k not in ("nested", "tuples")}
        return {k: v for k, v in meta.items() if v is not None}

    def to_xarray(self):
        """The result as an :class:`xarray.Dataset` (needs the optional ``xarray`` package).

        Each array field is a data variable with named dimensions (``time``, ``state``,
        ``measurement``, ``mode``, ``bound``…; see the class's ``_export_dims``) and the
        attributes ``units``; the static fields, ``kind`` and ``format_version`` are the
        dataset's ``attrs``. Tuples of arrays become ``name.0``, ``name.1``…; a nested result's
        fields are prefixed ``outer/``.

        **Returns:** an ``xarray.Dataset``. **Raises:** ``ImportError`` naming the extra when
        xarray is not installed.
        """
        try:
            import xarray as xr
        except ImportError as exc:  # pragma: no cover - depends on the environment
            raise ImportError("to_xarray needs xarray: pip install 'jaxtrack[export]'") from exc
        data_vars = {}
        for name, arr, dims, units in self._labelled():
            # bool arrays and 0-d scalars are kept as they are
            data_vars[name] = xr.Variable(dims, arr, attrs={"units": units} if units else {})
        return xr.Dataset(data_vars, attrs=self._attrs())

    def to_pandas(self):
        """The per-step curves as a :class:`pandas.DataFrame` (needs the optional ``pandas``).

        One row per step (index ``time``), one column per per-step quantity: a ``(T,)`` field is
        one column, a ``(T, n)`` field the columns ``name[0]`` … ``name[n-1]``, a ``(T, n, n)``
        field ``name[i,j]``. Fields without a time axis (``anees``, final states, flags) and the
        static fields go to ``DataFrame.attrs``, as do ``units`` (column → units).

        **Returns:** a ``pandas.DataFrame``. **Raises:** ``ImportError`` naming the extra when
        pandas is not installed; :class:`~jaxtrack.InputError` for a batch of results (leading
        ``batch_*`` axes): export one run at a time, or use :meth:`to_xarray`.
        """
        try:
            import pandas as pd
        except ImportError as exc:  # pragma: no cover - depends on the environment
            raise ImportError("to_pandas needs pandas: pip install 'jaxtrack[export]'") from exc
        columns, units, attrs = {}, {}, self._attrs()
        for name, arr, dims, unit in self._labelled():
            if dims and dims[0].startswith("batch_"):
                raise InputError(f"to_pandas exports one result; `{name}` has batch axes {arr.shape}. "
                                 "Index one run first, or use to_xarray().")
            if not dims or dims[0] != "time":
                attrs[name] = arr.tolist()
                continue
            flat = arr.reshape(arr.shape[0], -1)
            if arr.ndim == 1:
                labels = [name]
            else:
                labels = [f"{name}[{','.join(map(str, idx))}]" for idx in np.ndindex(*arr.shape[1:])]
            for j, label in enumerate(labels):
                columns[label] = flat[:, j]
                if unit:
                    units[label] = unit
        df = pd.DataFrame(columns)
        df.index.name = "time"
        df.attrs.update(attrs)
        df.attrs["units"] = units
        return df


def _optional(field: dataclasses.Field) -> bool:
    """Whether a field's annotation admits None (annotations are strings here)."""
    return "None" in str(field.type)


def _dims_for(ndim: int, base: tuple[str, ...] | None, name: str) -> tuple[str, ...]:
    """Dimension names for an array of ``ndim`` axes: ``base`` for the trailing ones, ``batch_i``
    for any leading ones; ``name_dim_i`` when no base is declared."""
    if base is None:
        return tuple(f"{name}_dim_{i}" for i in range(ndim))
    lead = ndim - len(base)
    if lead < 0:
        return tuple(base[-ndim:]) if ndim else ()
    return tuple(f"batch_{i}" for i in range(lead)) + tuple(base)
