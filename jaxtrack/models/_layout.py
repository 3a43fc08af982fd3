"""State layouts: what each component of a state vector is (position, velocity, … per axis).

A **layout** is a tuple of component names, one per state component, e.g. ``("x", "y", "vx",
"vy")`` for a 2-D constant-velocity state or ``("x", "y", "vx", "vy", "omega")`` for the
nearly-constant turn. Motion models declare theirs (:attr:`AbstractTransitionModel.state_layout
<jaxtrack.models.AbstractTransitionModel.state_layout>`; ``None`` where the model cannot know it,
e.g. a bare ``LinearTransition`` without ``state_layout=``), and the library checks against it what
would otherwise be silently wrong:

- a sensor's ``position_indices`` / ``velocity_indices`` must read positions / velocities
  (a 3-D radar on a 2-D state would read ``vx`` as height);
- the members of an :class:`~jaxtrack.filters.InteractingMultipleModel` are embedded in the
  common state by matching names (a 2-D and a 3-D constant-velocity member: the 2-D member's
  ``vx`` goes to the common ``vx``, not to ``z``).

Names (the field's usual symbols): positions ``x``, ``y``, ``z``; velocities ``vx``, ``vy``,
``vz``; accelerations ``ax``, ``ay``, ``az``; turn rate ``omega``. A model may use other names
for other quantities (biases, clock states); only these are interpreted.
"""

from __future__ import annotations

from collections.abc import Sequence

from .._validation import InputError

AXES = ("x", "y", "z")
#: The per-axis names of the kinematic derivatives, by order: position, velocity, acceleration.
KINEMATIC_PREFIXES = ("", "v", "a")
TURN_RATE = "omega"

Layout = tuple[str, ...]


def kinematic_layout(dim: int, order: int) -> Layout:
    """``[positions…, velocities…(, accelerations…)]`` of ``dim`` axes (the library's ordering).

    ``kinematic_layout(2, 2) == ("x", "y", "vx", "vy")``.
    """
    return tuple(p + a for p in KINEMATIC_PREFIXES[:order] for a in AXES[:dim])


def check_layout(name: str, layout: Sequence[str] | None, n: int) -> Layout | None:
    """``layout`` as a tuple of ``n`` distinct strings (or None); ``InputError`` naming ``name``."""
    if layout is None:
        return None
    if isinstance(layout, str) or not all(isinstance(c, str) for c in layout):
        raise InputError(f"`{name}` must be a sequence of component names (str), e.g. ('x', 'y', 'vx', 'vy'); "
                         f"got {layout!r}.")
    layout = tuple(layout)
    if len(layout) != n:
        raise InputError(f"`{name}` names {len(layout)} components but the state has {n}: {layout}.")
    if len(set(layout)) != n:
        raise InputError(f"`{name}` must name each state component once; got {layout}.")
    return layout


def _split(name: str) -> tuple[str, int] | None:
    """``"vy"`` → ``("v", 1)``; None for a name that is not a per-axis kinematic one."""
    for prefix in KINEMATIC_PREFIXES:
        if len(name) == len(prefix) + 1 and name.startswith(prefix) and name[-1] in AXES:
            return prefix, AXES.index(name[-1])
    return None


def shift_axes(layout: Layout, offset: int) -> Layout | None:
    """The layout of a block placed after ``offset`` spatial axes (``("x", "vx")`` +1 → ``("y", "vy")``).

    Used by :class:`~jaxtrack.models.BlockTransition`: a 1-D block does not know which axis it
    moves. None when an axis would pass ``z``.
    """
    out = []
    for c in layout:
        s = _split(c)
        if s is None:
            out.append(c)
        elif s[1] + offset >= len(AXES):
            return None
        else:
            out.append(s[0] + AXES[s[1] + offset])
    return tuple(out)


def num_axes(layout: Layout) -> int:
    """The number of spatial axes a layout's kinematic names use (``("x", "vx")`` → 1)."""
    axes = [s[1] for s in map(_split, layout) if s is not None]
    return max(axes) + 1 if axes else 0


def indices_of(layout: Layout, names: Sequence[str]) -> tuple[int, ...] | None:
    """Where ``names`` sit in ``layout`` (None if one is missing)."""
    try:
        return tuple(layout.index(c) for c in names)
    except ValueError:
        return None


def position_indices(layout: Layout) -> tuple[int, ...]:
    """The indices of ``x``, ``y``, ``z`` present in ``layout``, in axis order."""
    return tuple(layout.index(a) for a in AXES if a in layout)


def velocity_indices(layout: Layout) -> tuple[int, ...]:
    """The indices of ``vx``, ``vy``, ``vz`` present in ``layout``, in axis order."""
    return tuple(layout.index("v" + a) for a in AXES if "v" + a in layout)


def common_layout(layouts: Sequence[Layout]) -> tuple[Layout, tuple[tuple[int, ...], ...]]:
    """The union of several layouts and where each one's components sit in it.

    The union is the longest layout (the first of equal length), followed by the components the
    others add, in the order first met. Returns ``(common, indices)`` with ``indices[i][j]`` the
    position in ``common`` of component ``j`` of ``layouts[i]``.
    """
    base = max(layouts, key=len)
    common = list(base)
    for lay in layouts:
        common.extend(c for c in lay if c not in common)
    common = tuple(common)
    return common, tuple(tuple(common.index(c) for c in lay) for lay in layouts)
