"""The progress-bar class of the library: tqdm's notebook widget where ipywidgets can draw it.

``tqdm.auto`` picks the notebook widget inside a Jupyter kernel; without ipywidgets it warns
(``TqdmWarning: IProgress not found``) when imported and falls back to the text bar. ipywidgets is
not a dependency, so every notebook that imported jaxtrack (and the documentation gallery that
shows their outputs) opened with that warning. Choosing the text bar here when ipywidgets is
missing gives the same bar without the warning.
"""

from __future__ import annotations

import importlib.util

if importlib.util.find_spec("ipywidgets") is None:
    from tqdm.std import tqdm
else:
    from tqdm.auto import tqdm

__all__ = ["tqdm"]
