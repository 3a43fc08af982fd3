"""Execute notebooks at the small size and keep the executed copies for the documentation gallery.

One code path for the notebook test (``tests/test_notebooks.py``) and ``make docs``: each notebook
runs top to bottom in a fresh ``python3`` kernel with ``JAXTRACK_NOTEBOOK_SMALL=1`` and the
kernel's own (inline) matplotlib backend, so its figures come back as ``image/png`` outputs; the
executed notebook is written to ``docs/gallery/<name>.ipynb`` (atomically: a half-written file
would be rendered by mkdocs-jupyter as a broken page, or look up to date to make).

Usage (what ``make docs`` runs for each missing or stale copy)::

    python tools/execute_notebooks.py notebooks/quickstart.ipynb [more.ipynb ...]
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import nbformat
from nbclient import NotebookClient

ROOT = Path(__file__).resolve().parent.parent
NOTEBOOK_DIR = ROOT / "notebooks"
GALLERY_DIR = ROOT / "docs" / "gallery"
# Generous per-cell limit: on a loaded 2-core machine the first cell of a notebook also pays for
# JAX's import and the first compilations.
CELL_TIMEOUT_S = 600


def gallery_path(source: Path) -> Path:
    """Where the executed copy of notebook ``source`` lives: ``docs/gallery/<name>.ipynb``."""
    return GALLERY_DIR / Path(source).name


def execute_notebook(source: Path, workdir: Path) -> nbformat.NotebookNode:
    """Run notebook ``source`` in a fresh kernel at the small size; return the executed notebook.

    ``workdir`` is the kernel's working directory (whatever the notebook writes lands there).
    The small size is requested through the environment, which the kernel inherits;
    ``MPLBACKEND`` is removed so the kernel keeps its inline backend, as a user's Jupyter does.
    """
    nb = nbformat.read(source, as_version=4)
    saved = {k: os.environ.get(k) for k in ("JAXTRACK_NOTEBOOK_SMALL", "MPLBACKEND")}
    os.environ["JAXTRACK_NOTEBOOK_SMALL"] = "1"
    os.environ.pop("MPLBACKEND", None)
    try:
        client = NotebookClient(
            nb, timeout=CELL_TIMEOUT_S, kernel_name="python3", resources={"metadata": {"path": str(workdir)}}
        )
        client.execute()
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    return nb


def outputs(nb: nbformat.NotebookNode) -> list:
    """All outputs of the code cells of ``nb``, in order."""
    return [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])]


def image_outputs(nb: nbformat.NotebookNode) -> list:
    """The outputs of ``nb`` that carry a PNG figure."""
    return [
        o for o in outputs(nb) if o.output_type in ("display_data", "execute_result") and "image/png" in o.get("data", {})
    ]


def write_atomically(nb: nbformat.NotebookNode, dest: Path) -> None:
    """Write ``nb`` to ``dest`` through a temporary file in the same folder and ``os.replace``."""
    dest = Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{dest.name}.", suffix=".tmp", dir=dest.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            nbformat.write(nb, f)
        os.chmod(tmp, 0o644)  # mkstemp creates 0600; the copy is an ordinary, readable file
        os.replace(tmp, dest)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def main(argv: list[str]) -> int:
    if not argv:
        print(__doc__.strip().splitlines()[-1].strip(), file=sys.stderr)
        return 2
    for arg in argv:
        source = Path(arg)
        with tempfile.TemporaryDirectory() as workdir:
            nb = execute_notebook(source, Path(workdir))
        errors = [o for o in outputs(nb) if o.output_type == "error"]
        if errors:  # nbclient raises on a failing cell; an error output left anyway is a failure too
            print(f"{source.name}: {len(errors)} error output(s)", file=sys.stderr)
            return 1
        if not image_outputs(nb):
            print(f"{source.name} showed no figure", file=sys.stderr)
            return 1
        write_atomically(nb, gallery_path(source))
        print(f"executed {source} -> {gallery_path(source).relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
