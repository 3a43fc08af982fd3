"""Every notebook executes top to bottom at a small size and shows at least one figure.

The executed notebooks are kept as ``docs/gallery/<name>.ipynb`` (gitignored): ``make docs``
renders those copies instead of executing every notebook a second time (it executes only the
missing or stale ones, with the same function, ``tools/execute_notebooks.py``).
"""

import importlib.util
import os
from pathlib import Path

import pytest

from conftest import FAST_COMPILE_ENV

ROOT = Path(__file__).parent.parent
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))

_spec = importlib.util.spec_from_file_location("_execute_notebooks", ROOT / "tools" / "execute_notebooks.py")
execute_notebooks = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(execute_notebooks)


# Notebooks whose kernels compile at XLA's default level: as the test modules whose programs they
# share do (``pytest.mark.xla_optimized``, tests/conftest.py; at another level the two would
# compile everything twice instead of loading it from the persistent cache), or (None) because
# they run long programs that no test module shares: the Williams notebook's 2-run study is
# runtime-bound (the PMBM's Murty loops), 108 -> 63 s wall (113 -> 77 CPU-s) at the default level,
# cold cache, one process. The other notebooks are compile-bound and lose there
# (multitarget_first_tracker 48 -> 56 s, schedule_design 38 -> 41 s).
XLA_OPTIMIZED = {"maneuvering_imm.ipynb": "test_maneuvering.py", "particle_filters.ipynb": "test_tma_bounds.py",
                 "williams15_rfs.ipynb": None}


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.name)
def test_notebook_executes(path, tmp_path, monkeypatch):
    if path.name in XLA_OPTIMIZED and os.environ.get(FAST_COMPILE_ENV) == "1":
        monkeypatch.setenv(FAST_COMPILE_ENV, "0")  # the kernel inherits this process's environment
    # The kernel's own (inline) matplotlib backend, as a user's Jupyter has: the figures must
    # come back as image outputs (jaxtrack never switches the backend).
    nb = execute_notebooks.execute_notebook(path, tmp_path)
    errors = [o for o in execute_notebooks.outputs(nb) if o.output_type == "error"]
    assert not errors
    assert len(execute_notebooks.image_outputs(nb)) >= 1, f"{path.name} showed no figure"
    # The gallery shows every output: no tqdm warning (jaxtrack/_progress.py picks the text bar
    # without ipywidgets instead of letting tqdm.auto warn).
    warned = [o for o in execute_notebooks.outputs(nb) if "IProgress not found" in str(o.get("text", ""))]
    assert not warned, f"{path.name} shows tqdm's IProgress warning"
    # Only a notebook that passed becomes the gallery's copy.
    execute_notebooks.write_atomically(nb, execute_notebooks.gallery_path(path))


def test_there_are_notebooks():
    assert NOTEBOOKS, "notebooks/ holds no notebook"


def test_write_atomically_replaces_and_leaves_no_temporary(tmp_path):
    import nbformat

    dest = tmp_path / "gallery" / "x.ipynb"
    for text in ("first", "second"):
        nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_markdown_cell(text)])
        execute_notebooks.write_atomically(nb, dest)
    assert nbformat.read(dest, as_version=4).cells[0].source == "second"
    assert [p.name for p in dest.parent.iterdir()] == ["x.ipynb"]


def test_optimized_notebooks_share_their_tests_level():
    """A notebook listed in XLA_OPTIMIZED shares programs with a module marked xla_optimized, or
    (None) with no module at all."""
    for notebook, module in XLA_OPTIMIZED.items():
        assert (ROOT / "notebooks" / notebook).exists()
        if module is not None:
            assert "pytestmark = pytest.mark.xla_optimized" in (ROOT / "tests" / module).read_text(), module
