"""Rows of a reproduction table: one reference number against jaxtrack's value, with where the
reference comes from (printed in the paper, derived in the specification, or a study's own claim)."""

from __future__ import annotations

import contextlib
import dataclasses
import math
import os
import tempfile
from pathlib import Path

SOURCES = ("paper", "spec", "claim")
"""Where a row's reference number comes from, in the order the summary counts them."""

SOURCE_LABELS = {"paper": "printed in the papers", "spec": "derived in the specifications",
                 "claim": "stated claims"}
"""The summary line's words for each source."""

BOUNDS = ("close", "interval", "at_most", "at_least")

MAX_CLOSE_RTOL = 0.5
"""The widest relative tolerance a ``close`` row may have: a wider one is an interval in disguise
(or cannot fail), and must be written as ``bound="interval"``/``"at_most"``/``"at_least"``."""


@dataclasses.dataclass(frozen=True)
class PaperRow:
    """One reproduced number.

    - ``id``: the verification-target id of the study's spec (e.g. ``"T16"``); several rows may
      share one id when a target has several numbers.
    - ``quantity``: what is compared, with units.
    - ``paper``: the reference value: for ``close`` the number compared to, for ``at_most`` /
      ``at_least`` the bound; ``None`` for ``interval`` rows (their reference is ``lo``/``hi``).
    - ``value``: jaxtrack's value.
    - ``rtol``: the relative tolerance of a ``close`` row: the spec's tolerance, or half a unit in
      the paper's last printed digit when that is coarser (a 2-digit percentage cannot agree to
      5e-3). At most :data:`MAX_CLOSE_RTOL`; unused (0) for the other bounds.
    - ``bound``: ``"close"`` (default: ``|value − paper| ≤ rtol·|paper|``), ``"interval"``
      (``lo ≤ value ≤ hi``: the spec's margins and check ranges), ``"at_most"`` (``value ≤ paper``)
      or ``"at_least"`` (``value ≥ paper``).
    - ``source`` (keyword, required): ``"paper"`` when the reference number is printed in the paper
      (after the spec's documented OCR corrections), ``"spec"`` when it is a reference value
      derived or computed in the specification (not printed in the paper), ``"claim"`` for a
      study's own stated claim (our own scenario, not a paper's).
    - ``lo``, ``hi`` (keyword): the closed interval of an ``interval`` row; ``None`` otherwise.

    **Raises:** ``ValueError`` naming the field for an unknown ``bound`` or ``source``, a ``close``
    row with ``rtol`` outside ``[0, 0.5]``, or an interval without ordered ``lo``/``hi``.
    """

    id: str
    quantity: str
    paper: float | None
    value: float
    rtol: float = 0.0
    bound: str = "close"
    _: dataclasses.KW_ONLY
    source: str
    lo: float | None = None
    hi: float | None = None

    def __post_init__(self):
        if self.bound not in BOUNDS:
            raise ValueError(f"`bound` must be one of {BOUNDS}; got {self.bound!r}.")
        if self.source not in SOURCES:
            raise ValueError(f"`source` must be one of {SOURCES}; got {self.source!r} ({self.id} {self.quantity}).")
        if self.bound == "interval":
            if self.lo is None or self.hi is None or not self.lo <= self.hi or self.paper is not None:
                raise ValueError(f"an interval row needs `lo` ≤ `hi` and `paper` None; got lo={self.lo!r}, "
                                 f"hi={self.hi!r}, paper={self.paper!r} ({self.id} {self.quantity}).")
            return
        if self.lo is not None or self.hi is not None:
            raise ValueError(f"`lo`/`hi` are for bound='interval' only ({self.id} {self.quantity}).")
        if self.paper is None:
            raise ValueError(f"`paper` is required for bound={self.bound!r} ({self.id} {self.quantity}).")
        # Why: a relative tolerance above 0.5 accepts anything from half to 1.5 times the reference
        # (rtol ≥ 1 accepts 0): such a row is an interval in disguise or cannot fail.
        if self.bound == "close" and not 0.0 <= self.rtol <= MAX_CLOSE_RTOL:
            raise ValueError(f"`rtol` of a close row must be in [0, {MAX_CLOSE_RTOL}]; got {self.rtol!r} "
                             f"({self.id} {self.quantity}); write a wider margin as bound='interval'.")

    @classmethod
    def interval(cls, id: str, quantity: str, lo: float, hi: float, value: float, *, source: str) -> PaperRow:
        """A row that passes iff ``lo ≤ value ≤ hi`` (the spec's margins and check ranges).

        **Arguments:** ``id``, ``quantity``, ``value`` as for :class:`PaperRow`; ``lo``, ``hi``: the
        closed interval; ``source``: ``"paper"``, ``"spec"`` or ``"claim"``.

        **Returns:** a :class:`PaperRow` with ``bound="interval"`` and ``paper=None``.
        """
        return cls(id, quantity, None, float(value), 0.0, "interval", source=source, lo=float(lo), hi=float(hi))

    @property
    def ok(self) -> bool:
        """Whether ``value`` is finite and meets the row's bound."""
        if not math.isfinite(self.value):
            return False
        if self.bound == "interval":
            return bool(self.lo <= self.value <= self.hi)
        if self.bound == "at_most":
            return bool(self.value <= self.paper)
        if self.bound == "at_least":
            return bool(self.value >= self.paper)
        return bool(abs(self.value - self.paper) <= self.rtol * abs(self.paper))

    def as_dict(self) -> dict:
        """The row as JSON-ready dict, every key always present (schema_version 1 of
        ``jaxtrack/cli/schemas/reproduce.schema.json``): ``id``, ``quantity``, ``source``,
        ``bound``, ``paper`` (None for intervals), ``lo``/``hi`` (None unless interval),
        ``value`` (None when not finite: JSON has no NaN), ``rtol`` (None unless close) and ``ok``."""
        value = self.value if math.isfinite(self.value) else None
        return {"id": self.id, "quantity": self.quantity, "source": self.source, "bound": self.bound,
                "paper": self.paper, "lo": self.lo, "hi": self.hi, "value": value,
                "rtol": self.rtol if self.bound == "close" else None, "ok": self.ok}

    def reference_text(self) -> str:
        """The reference column of the table: ``x`` (close), ``[lo, hi]``, ``≤ x`` or ``≥ x``."""
        if self.bound == "interval":
            return f"[{self.lo:.4g}, {self.hi:.4g}]"
        prefix = {"at_most": "≤ ", "at_least": "≥ "}.get(self.bound, "")
        return f"{prefix}{self.paper:.6g}"


def count_by_source(rows) -> dict[str, list[int]]:
    """``{source: [passed, total]}`` for every source in :data:`SOURCES` (zeros included).

    **Arguments:** ``rows``: :class:`PaperRow` entries, or their :meth:`PaperRow.as_dict` dicts.

    **Returns:** a dict of two-int lists, keyed in :data:`SOURCES` order.
    """
    out = {s: [0, 0] for s in SOURCES}
    for r in rows:
        source, ok = (r["source"], r["ok"]) if isinstance(r, dict) else (r.source, r.ok)
        out[source][0] += bool(ok)
        out[source][1] += 1
    return out


def summary_line(counts: dict[str, list[int]], num_studies: int) -> str:
    """One line: the pass counts per source (sources with no rows left out), then the total.

    e.g. ``printed in the papers: 97/97 · derived in the specifications: 303/303 · stated claims:
    7/7 · 407/407 within tolerance across 6 studies``.

    **Arguments:** ``counts``: from :func:`count_by_source`; ``num_studies``: how many studies.

    **Returns:** the line, a str.
    """
    parts = [f"{SOURCE_LABELS[s]}: {p}/{t}" for s, (p, t) in counts.items() if t]
    passed = sum(p for p, _ in counts.values())
    total = sum(t for _, t in counts.values())
    parts.append(f"{passed}/{total} within tolerance across {num_studies} stud{'y' if num_studies == 1 else 'ies'}")
    return " · ".join(parts)


def printed_rtol(paper: float, last_digit: float, floor: float = 5e-3) -> float:
    """Tolerance for a number printed to ``last_digit`` (e.g. 0.01): ``max(floor, ½·last_digit/|paper|)``.

    **Arguments:**

    - ``paper``: the printed value (non-zero); ``last_digit``: the place value of its last printed
      digit; ``floor``: the smallest tolerance returned (default 5e-3).

    **Returns:** the relative tolerance, a Python float.
    """
    return max(floor, 0.5 * last_digit / abs(paper))


def format_rows(rows: list[PaperRow], title: str) -> str:
    """A plain-text table of reproduced numbers, one line per row, and the pass counts by source.

    The ``src`` column says where the reference comes from (``paper``, ``spec``, ``claim``); the
    ``reference`` column holds the number, ``[lo, hi]`` for an interval, or ``≤ x`` / ``≥ x``.

    **Arguments:**

    - ``rows``: the :class:`PaperRow` entries; ``title``: the first line.

    **Returns:** the table, a str.
    """
    head = f"{'id':<5} {'src':<5} {'quantity':<72} {'reference':>20} {'jaxtrack':>12} {'rtol':>7}  ok"
    lines = [title, head, "-" * len(head)]
    for r in rows:
        tol = f"{r.rtol:.1e}" if r.bound == "close" else "-"
        lines.append(
            f"{r.id:<5} {r.source:<5} {r.quantity[:72]:<72} {r.reference_text():>20} {r.value:>12.6g} {tol:>7}  "
            f"{'yes' if r.ok else 'NO'}"
        )
    lines.append(summary_line(count_by_source(rows), 1).rsplit(" across ", 1)[0])
    return "\n".join(lines)


@contextlib.contextmanager
def atomic_path(path):
    """Write a file whole or not at all: yields a temporary path in the target's folder, renamed
    onto ``path`` when the block ends normally and deleted when it raises (Ctrl-C included).

    The temporary file is hidden (``.name.XXXX.part``) and on the same file system, so the
    rename is atomic: a reader never sees a partial file under ``path``.

    **Arguments:** ``path``: the final file (its folder must exist). **Returns:** a context
    manager yielding the temporary ``Path``.
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".part")
    os.close(fd)
    try:
        yield Path(tmp)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def write_figures(out_dir, makers, dpi: int = 120) -> list[str]:
    """Build each figure with its maker and save it as PNG: ``makers`` is ``[(file_name, make), …]``
    with ``make() -> matplotlib Figure``. Creates ``out_dir``; returns the written paths.

    Each file is written to a temporary name and renamed (:func:`atomic_path`), so an
    interrupted call leaves only complete figures.

    **Arguments:**

    - ``out_dir``: the output directory (str or path), created if missing.
    - ``makers``: ``[(file_name, make), …]``; ``dpi``: the PNG resolution (default 120).

    **Returns:** the written file paths, a list of str.
    """
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, make in makers:
        fig = make()
        try:
            with atomic_path(out / name) as tmp:
                fig.savefig(tmp, dpi=dpi, format=Path(name).suffix.lstrip(".") or "png")
        finally:
            plt.close(fig)
        paths.append(str(out / name))
    return paths
