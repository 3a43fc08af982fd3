"""Renamed result fields: the old name keeps working for one release, with a ``DeprecationWarning``.

The library has one naming of results (docs/conventions.md, "Names of results"): a quantity over
the time axis is named by which estimate it is, ``filtered_mean``, ``predicted_cov``,
``smoothed_mean``. A result class that used another name declares the old one with
:func:`renamed`, so existing code runs and is told what to write instead.
"""

from __future__ import annotations

import warnings

from ._validation import InputError

#: The release in which the deprecated aliases are removed.
REMOVED_IN = "0.3"


def renamed(old: str, new: str) -> property:
    """A read-only property ``old`` returning ``self.<new>`` with a ``DeprecationWarning``.

    **Arguments:** ``old``, ``new``: the field's former and current names.
    **Returns:** a ``property`` to assign to ``old`` in the class body.
    """

    def getter(self):
        warnings.warn(
            f"`{type(self).__name__}.{old}` is deprecated: use `.{new}` (one naming of results across "
            f"filters, smoothers and the IMM; see the conventions page). `.{old}` will be removed in "
            f"jaxtrack {REMOVED_IN}.",
            DeprecationWarning,
            stacklevel=2,
        )
        return getattr(self, new)

    return property(getter, doc=f"Deprecated alias of ``{new}`` (removed in jaxtrack {REMOVED_IN}).")


def keyword_args(cls: str, first, args: tuple, old_order: tuple[str, ...], given: dict) -> dict:
    """The constructor's arguments by name, accepting the deprecated positional form for one release.

    The motion models take the sample period first and everything else by keyword, so that one
    call shape fits all of them (``CoordinatedTurn`` used to take the turn rate first, the others
    the period: issue 37). A call with more positional arguments is read in the old order
    ``old_order`` with a ``DeprecationWarning`` that spells the new call.

    **Raises:** ``TypeError`` for too many positional arguments or one given twice (as Python
    would), ``InputError`` naming a required keyword that is missing.
    """
    if args:
        values = (first,) + args
        if len(values) > len(old_order):
            raise TypeError(f"{cls}() takes at most {len(old_order)} positional arguments ({len(values)} given).")
        legacy = dict(zip(old_order, values))
        for name in legacy:
            if name != "sample_period" and given.get(name) is not None:
                raise TypeError(f"{cls}() got multiple values for argument {name!r}.")
        given = {**given, **legacy}
        spelled = ", ".join([repr(legacy.get("sample_period", "tau"))]
                            + [f"{k}={v!r}" for k, v in legacy.items() if k != "sample_period"])
        warnings.warn(
            f"{cls}: positional arguments after the sample period are deprecated (one call shape for every "
            f"motion model); write {cls}({spelled}). The positional form stops working in jaxtrack {REMOVED_IN}.",
            DeprecationWarning, stacklevel=3)
    else:
        given = {"sample_period": first, **given}
    if missing := [k for k in old_order if given.get(k) is None]:
        raise InputError(f"{cls}: `{missing[0]}` is required (keyword), e.g. {cls}(1.0, "
                         + ", ".join(f"{k}=..." for k in old_order if k != "sample_period") + ").")
    return given
