"""Rows of a reproduction table: one printed paper number against jaxtrack's value."""

from __future__ import annotations

import contextlib
import dataclasses
import math
import os
import tempfile
from pathlib import Path


@dataclasses.dataclass(frozen=True)
class PaperRow:
    """One reproduced number.

    - ``id``: the verification-target id of the study's spec (e.g. ``"T16"``); several rows may
      share one id when a target has several numbers.
    - ``quantity``: what is compared, with units.
    - ``paper``: the value printed in the paper (after the spec's documented OCR corrections).
    - ``value``: jaxtrack's value.
    - ``rtol``: the relative tolerance: the spec's tolerance, or half a unit in the paper's last
      printed digit when that is coarser (a 2-digit percentage cannot agree to 5e-3).
    - ``bound``: ``"close"`` (default: ``|value − paper| ≤ rtol·|paper|``), or for a study's own
      stated claim ``"at_most"`` (``value ≤ paper``) / ``"at_least"`` (``value ≥ paper``); ``paper``
      is then the claimed bound and ``rtol`` is not used.
    """

    id: str
    quantity: str
    paper: float
    value: float
    rtol: float
    bound: str = "close"

    def __post_init__(self):
        if self.bound not in ("close", "at_most", "at_least"):
            raise ValueError(f"`bound` must be 'close', 'at_most' or 'at_least'; got {self.bound!r}.")

    @property
    def ok(self) -> bool:
        if not math.isfinite(self.value):
            return False
        if self.bound == "at_most":
            return bool(self.value <= self.paper)
        if self.bound == "at_least":
            return bool(self.value >= self.paper)
        return bool(abs(self.value - self.paper) <= self.rtol * abs(self.paper))

    def as_dict(self) -> dict:
        out = {"id": self.id, "quantity": self.quantity, "paper": self.paper, "value": self.value,
               "rtol": self.rtol, "ok": self.ok}
        if self.bound != "close":
            out["bound"] = self.bound
        return out


def printed_rtol(paper: float, last_digit: float, floor: float = 5e-3) -> float:
    """Tolerance for a number printed to ``last_digit`` (e.g. 0.01): ``max(floor, ½·last_digit/|paper|)``.

    **Arguments:**

    - ``paper``: the printed value (non-zero); ``last_digit``: the place value of its last printed
      digit; ``floor``: the smallest tolerance returned (default 5e-3).

    **Returns:** the relative tolerance, a Python float.
    """
    return max(floor, 0.5 * last_digit / abs(paper))


def format_rows(rows: list[PaperRow], title: str) -> str:
    """A plain-text table of reproduced numbers, one line per row, and a pass count.

    **Arguments:**

    - ``rows``: the :class:`PaperRow` entries; ``title``: the first line.

    **Returns:** the table, a str.
    """
    head = f"{'id':<5} {'quantity':<72} {'paper':>11} {'jaxtrack':>12} {'rtol':>7}  ok"
    lines = [title, head, "-" * len(head)]
    for r in rows:
        tol = {"at_most": "≤ paper", "at_least": "≥ paper"}.get(r.bound, f"{r.rtol:.1e}")
        lines.append(
            f"{r.id:<5} {r.quantity[:72]:<72} {r.paper:>11.6g} {r.value:>12.6g} {tol:>7}  "
            f"{'yes' if r.ok else 'NO'}"
        )
    passed = sum(r.ok for r in rows)
    lines.append(f"{passed}/{len(rows)} reproduced within tolerance")
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
