"""Renamed result fields: the old name keeps working for one release, with a ``DeprecationWarning``.

The library has one naming of results (docs/conventions.md, "Names of results"): a quantity over
the time axis is named by which estimate it is, ``filtered_mean``, ``predicted_cov``,
``smoothed_mean``. A result class that used another name declares the old one with
:func:`renamed`, so existing code runs and is told what to write instead.
"""

from __future__ import annotations

import warnings

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
