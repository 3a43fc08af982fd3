"""Check a built documentation site: figures, API reference, typeset math, no tqdm warning.

Run by ``make docs`` after ``mkdocs build``::

    python tools/check_site.py [build/site]
    python tools/check_site.py [build/site] --browser [--screenshots DIR]   # also in Chromium

- Gallery: for every notebook in ``notebooks/``, its page ``gallery/<name>/index.html`` exists and
  holds at least one embedded PNG figure (``<img`` with ``data:image/png``).
- API: every name in every public ``__all__`` (``PUBLIC_MODULES``) has its anchor
  ``id="jaxtrack.<module>.<Name>"`` in the built reference.
- Math: each page of ``MATH_PAGES`` (a Markdown page, an API page, a notebook page) holds KaTeX
  output (``class="katex"``), and no page holds TeX left untypeset (``class="arithmatex"``) or a
  MathJax loader (the site typesets at build time: tools/mkdocs_hooks.py).
- No page shows tqdm's ``IProgress not found`` warning (a gallery page would, from a notebook
  executed before jaxtrack/_progress.py chose the text bar: run the notebooks again).
- ``--browser``: opens the ``MATH_PAGES`` in headless Chromium, served from this machine, and
  checks in the page's DOM that its ``.katex`` nodes hold MathML that the browser laid out (a
  ``math`` element with a non-empty box), that no TeX source shows in the page's text, and that
  the tqdm warning does not show; saves one screenshot per page, scrolled to its first displayed
  formula, to ``--screenshots`` (default ``build/site-check``). Chromium is not a dependency:
  without it this mode says how to install it and exits 2; the checks above need no browser.

The ``__all__`` lists are read from the source files (``ast``), so the check does not import JAX.
Exits 1 with one line per problem.
"""

from __future__ import annotations

import argparse
import ast
import functools
import http.server
import json
import re
import shutil
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
# The public layers, one API page each (docs/api/<name>.md).
PUBLIC_MODULES = (
    "models",
    "filters",
    "montecarlo",
    "sensitivity",
    "covariance",
    "design",
    "estimation",
    "geometry",
    "learning",
    "bounds",
    "plotting",
    "association",
    "fusion",
    "multitarget",
)
# Names of the top-level ``jaxtrack.__all__`` that are documented objects (the rest are the
# subpackages themselves and ``__version__``), with the path they are documented at:
# ``InputError`` is imported lazily (PEP 562), so griffe documents it where it is defined.
TOP_LEVEL_DOCUMENTED = {"InputError": "jaxtrack._validation.InputError"}
# Pages that show formulas, one of each source: a Markdown page, docstrings, a notebook.
MATH_PAGES = ("conventions/index.html", "api/sensitivity/index.html", "gallery/ho_sensitivity/index.html")
TQDM_WARNING = "IProgress not found"
CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")


def module_file(module: str) -> Path:
    """The source file of ``jaxtrack.<module>`` (a package's ``__init__.py`` or a module file)."""
    package = ROOT / "jaxtrack" / module / "__init__.py"
    return package if package.exists() else ROOT / "jaxtrack" / f"{module}.py"


def read_all(path: Path) -> list[str]:
    """The literal ``__all__`` list assigned in ``path`` (every public module has one)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets):
            return [ast.literal_eval(e) for e in node.value.elts if isinstance(e, ast.Constant)]
    raise LookupError(f"{path.relative_to(ROOT)} has no __all__")


def documented_paths() -> list[str]:
    """Every object path the API reference must document: ``jaxtrack.<module>.<Name>``."""
    paths = [f"jaxtrack.{m}.{name}" for m in PUBLIC_MODULES for name in read_all(module_file(m))]
    return paths + list(TOP_LEVEL_DOCUMENTED.values())


def figures_in(html: str) -> int:
    """Number of embedded PNG images in one HTML page."""
    return len(re.findall(r"<img[^>]*data:image/png", html))


def raw_display_math(html: str) -> bool:
    """Whether a page's text shows ``$$`` (TeX a reader would see as source): outside scripts,
    styles, code and KaTeX's own TeX annotations."""
    text = re.sub(r"<(script|style|code|pre|annotation)\b.*?</\1>", "", html, flags=re.S | re.I)
    return "$$" in text


def math_problems(site: Path) -> list[str]:
    """Formulas untypeset, a math page without KaTeX output, a MathJax loader, the tqdm warning."""
    problems = []
    for rel in MATH_PAGES:
        page = site / rel
        n = page.read_text(encoding="utf-8").count('class="katex"') if page.exists() else 0
        print(f"{rel}: {n} formula(s)")
        if n < 1:
            problems.append(f"math: {rel} shows no typeset formula")
    for page in sorted(site.rglob("*.html")):
        html = page.read_text(encoding="utf-8")
        rel = page.relative_to(site)
        if 'class="arithmatex"' in html:
            problems.append(f"math: {rel} holds TeX left untypeset")
        if raw_display_math(html):
            problems.append(f"math: {rel} shows a raw $$ formula (a display block arithmatex did not take, e.g. "
                            "a `.. math::` indented inside a docstring's list item)")
        if "MathJax" in html:
            problems.append(f"math: {rel} loads MathJax (the site typesets at build time)")
        if TQDM_WARNING in html:
            problems.append(f"{rel} shows tqdm's '{TQDM_WARNING}' warning: execute its notebook again")
    return problems


def check(site: Path) -> list[str]:
    problems = []
    notebooks = sorted((ROOT / "notebooks").glob("*.ipynb"))
    if not notebooks:
        problems.append("notebooks/ holds no notebook")
    for nb in notebooks:
        page = site / "gallery" / nb.stem / "index.html"
        if not page.exists():
            problems.append(f"gallery: no page for {nb.name} ({page.relative_to(site)})")
            continue
        n = figures_in(page.read_text(encoding="utf-8"))
        print(f"gallery/{nb.stem}: {n} figure(s)")
        if n < 1:
            problems.append(f"gallery: {nb.name} is rendered without a figure")
    anchors = set()
    for page in (site / "api").rglob("*.html"):
        anchors.update(re.findall(r'id="(jaxtrack[\w.]*)"', page.read_text(encoding="utf-8")))
    expected = documented_paths()
    missing = [p for p in expected if p not in anchors]
    problems += [f"API reference: no entry for {p}" for p in missing]
    print(f"API reference: {len(expected) - len(missing)}/{len(expected)} public names documented")
    return problems + math_problems(site)


# The browser check: a page of ours holds the site's page in a same-origin frame, measures it
# once loaded and writes the result into its own DOM, which Chromium prints (--dump-dom).
PROBE = r"""<!doctype html><html><body style="margin:0">
<iframe id="page" src="/{page}" style="width:1280px;height:1000px;border:0"></iframe>
<pre id="result">pending</pre>
<script>
const frame = document.getElementById("page");
frame.addEventListener("load", () => {{
  const doc = frame.contentDocument;
  const nodes = [...doc.querySelectorAll(".katex")];
  const laidOut = nodes.filter(n => {{
    const m = n.querySelector("math");
    if (!(m instanceof frame.contentWindow.MathMLElement)) return false;  // the frame's own class
    const box = m.getBoundingClientRect();
    return box.width > 0 && box.height > 0;
  }});
  const text = doc.body.innerText;
  const first = doc.querySelector(".katex-display") || nodes[0];
  if (first) first.scrollIntoView({{block: "center"}});
  document.getElementById("result").textContent = JSON.stringify({{
    katex: nodes.length, laid_out: laidOut.length,
    tex_shown: /\\(frac|partial|hat|sum|left|big)\b|\$\$/.test(text),
    tqdm_warning: text.includes({warning}),
  }});
}});
</script></body></html>"""


def find_chromium() -> str | None:
    return next((p for p in map(shutil.which, CHROMIUM_NAMES) if p), None)


def serve(site: Path) -> http.server.ThreadingHTTPServer:
    """The site on 127.0.0.1 (a free port), with each probe page at ``/__probe__/<page>``."""

    class Handler(http.server.SimpleHTTPRequestHandler):
        def do_GET(self):
            if self.path.startswith("/__probe__/"):
                body = PROBE.format(page=self.path.removeprefix("/__probe__/"), warning=json.dumps(TQDM_WARNING))
                data = body.encode("utf-8")
                self.send_response(200)
                self.send_header("Content-Type", "text/html; charset=utf-8")
                self.send_header("Content-Length", str(len(data)))
                self.end_headers()
                self.wfile.write(data)
            else:
                super().do_GET()

        def log_message(self, *args):
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(Handler, directory=str(site)))
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server


def browser_check(site: Path, shots: Path, chromium: str) -> list[str]:
    """Open each of ``MATH_PAGES`` in headless Chromium: DOM checks, one screenshot each."""
    problems = []
    shots.mkdir(parents=True, exist_ok=True)
    server = serve(site)
    try:
        with tempfile.TemporaryDirectory() as profile:
            # --no-sandbox: Chromium refuses to run as root with its sandbox (containers, CI).
            base = [chromium, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                    f"--user-data-dir={profile}", "--virtual-time-budget=10000", "--window-size=1280,1000"]
            for rel in MATH_PAGES:
                url = f"http://127.0.0.1:{server.server_port}/__probe__/{rel.removesuffix('index.html')}"
                dom = subprocess.run([*base, "--dump-dom", url], capture_output=True, text=True, timeout=120).stdout
                m = re.search(r'<pre id="result">(.*?)</pre>', dom, re.S)
                try:
                    result = json.loads(m.group(1)) if m else None
                except ValueError:
                    result = None
                shot = shots / (rel.removesuffix("/index.html").replace("/", "_") + ".png")
                subprocess.run([*base, f"--screenshot={shot}", url], capture_output=True, timeout=120)
                print(f"chromium {rel}: {result}; screenshot {shot}")
                if not result:
                    problems.append(f"browser: {rel} could not be measured")
                    continue
                if result["laid_out"] < 1:
                    problems.append(f"browser: {rel} shows no laid-out formula ({result['katex']} KaTeX node(s))")
                if result["tex_shown"]:
                    problems.append(f"browser: {rel} shows TeX source as text")
                if result["tqdm_warning"]:
                    problems.append(f"browser: {rel} shows tqdm's '{TQDM_WARNING}' warning")
    finally:
        server.shutdown()
    return problems


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("site", nargs="?", type=Path, default=ROOT / "build" / "site")
    parser.add_argument("--browser", action="store_true", help="also check the math pages in headless Chromium")
    parser.add_argument("--screenshots", type=Path, default=ROOT / "build" / "site-check")
    args = parser.parse_args(argv)
    site = args.site
    if not (site / "index.html").exists():
        print(f"{site} holds no built site (run mkdocs build first)", file=sys.stderr)
        return 1
    problems = check(site)
    if args.browser:
        chromium = find_chromium()
        if chromium is None:
            for p in problems:
                print(p, file=sys.stderr)
            print(
                f"--browser: no Chromium found ({', '.join(CHROMIUM_NAMES)} on PATH). It is not a dependency of "
                "jaxtrack; install it (Debian/Ubuntu: apt-get install -y chromium) to run the browser check. "
                "The checks above ran without it.",
                file=sys.stderr,
            )
            return 2
        problems += browser_check(site, args.screenshots, chromium)
    for p in problems:
        print(p, file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
