"""The notebooks as a static site (``make book``): one page per committed notebook, shown
with its committed outputs (nothing is executed), the overview's map as the front page and
table of contents, and MathJax served from the site itself, so it works offline.

Sphinx with MyST-NB (what Jupyter Book 1 is built on) does the rendering. The pages are the
numbered notebooks present in ``notebooks/``, so new notebooks appear without editing
anything; the map's rows link to them. The repository's notation and glossary
(``GLOSSARY.md``) is a page of its own.

    python -m oapo_lite book [--out build/book]
"""
from __future__ import annotations

import argparse
import ast
import errno
import importlib.util
import re
import shutil
import subprocess
import sys
from pathlib import Path

import nbformat

from oapo_lite import cli
from oapo_lite.study.runs.reproduce import NOTEBOOKS, ROOT, notebook_paths

OVERVIEW = "00_overview"

CONF = '''\
project = "oapo-lite"
copyright = "the oapo-lite authors"
extensions = ["myst_nb"]
myst_enable_extensions = ["dollarmath", "amsmath"]
nb_execution_mode = "off"  # the committed outputs are the results
exclude_patterns = ["_build"]
html_theme = "sphinx_book_theme"
html_title = "oapo-lite"
html_static_path = ["_static"]
mathjax_path = "mathjax/tex-mml-chtml.js"  # relative to _static: no CDN
html_favicon = "_static/favicon.svg"
html_context = {"default_mode": "light"}  # else the theme logs "Got invalid theme mode" as an error
'''
# Without a favicon the browser asks the server for /favicon.ico and logs the 404 as an error.
FAVICON = ('<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 16 16">'
           '<rect width="16" height="16" fill="#1f4e79"/></svg>\n')


def overview_map(path: Path) -> list[tuple[str, str, str]]:
    """The ``MAP = [(what, notebook stem, function), ...]`` literal of the overview notebook."""
    for cell in nbformat.read(path, as_version=4).cells:
        if cell.cell_type != "code" or "MAP" not in cell.source:
            continue
        for node in ast.parse(cell.source).body:
            if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "MAP" for t in node.targets):
                return [tuple(row) for row in ast.literal_eval(node.value)]
    raise ValueError(f"{path} has no cell assigning MAP = [(what, notebook, function), ...]")


def title(path: Path) -> str:
    """The notebook's first heading (the page title Sphinx will use), else its file stem."""
    for cell in nbformat.read(path, as_version=4).cells:
        if cell.cell_type == "markdown":
            for line in cell.source.splitlines():
                if line.startswith("# "):
                    return line[2:].strip()
    return path.stem


def index_page(rows: list[tuple[str, str, str]], paths: list[Path]) -> str:
    """The front page: every notebook present, in order, linked, with the map's rows that it
    rebuilds (what, and the function that implements it) beneath, then the table of contents."""
    lines = ["# oapo-lite: the notebooks", "",
             "Every equation, lemma and figure of the paper, the notebook that rebuilds it and the "
             f"function that implements it: the map of [the overview](notebooks/{OVERVIEW}.ipynb). "
             "The pages show the notebooks with their committed outputs.", ""]
    for path in paths:
        lines += [f"## [{title(path)}](notebooks/{path.stem}.ipynb)", ""]
        lines += [f"* {what}: `{function}`" for what, stem, function in rows if stem == path.stem]
        lines.append("")
    absent = [(what, stem) for what, stem, _ in rows if stem not in {p.stem for p in paths}]
    if absent:
        lines += ["## In the map, without a notebook here", ""] + [f"* {what}: {stem}" for what, stem in absent] + [""]
    lines += ["The symbols and the repository's own words are in [the notation and glossary](glossary.md).", ""]
    lines += ["```{toctree}", ":hidden:", ":caption: Notebooks", "", "glossary"] + [f"notebooks/{p.stem}" for p in paths]
    return "\n".join(lines + ["```", ""])


# the book's packages (book-requirements.txt, which pins them) by the module each is imported as
PACKAGES = {"sphinx": "Sphinx", "myst_nb": "myst-nb", "sphinx_book_theme": "sphinx-book-theme",
            "mathjax": "django-static-mathjax"}


def check_packages() -> None:
    """Refuse to start without the book's packages, naming them and the step that installs them
    (an import error alone names a module, e.g. 'mathjax', that no package is called)."""
    missing = [package for module, package in PACKAGES.items() if importlib.util.find_spec(module) is None]
    if missing:
        raise ImportError(f"the book needs {missing}, which are not installed; run `make book-deps` (or "
                          "pip install -r book-requirements.txt)")


def mathjax_dir() -> Path:
    """MathJax 3's browser files, from the ``django-static-mathjax`` wheel (book-requirements.txt)."""
    import mathjax

    path = Path(mathjax.__file__).parent / "static" / "mathjax" / "es5"
    if not (path / "tex-mml-chtml.js").exists():
        raise FileNotFoundError(f"no MathJax at {path}; install book-requirements.txt")
    return path


SOURCES_MARK = ".oapo-book-sources"  # marks <out>-src as the book's own, which a new build may replace


def build(out: Path, notebooks: Path = NOTEBOOKS, quiet: bool = True) -> Path:
    """Write the Sphinx sources next to ``out`` and build the HTML site into ``out``; returns
    the site's index.html."""
    out = cli.output_folder(str(out), "--out")
    src = out.parent / f"{out.name}-src"
    if out.exists() and any(out.iterdir()) and not (out / ".buildinfo").exists():  # Sphinx's mark of its output
        raise ValueError(f"--out {out} holds files the book did not write; allowed: an empty or new folder, or the "
                         "book's own earlier build")
    if src.exists() and not (src / SOURCES_MARK).exists():  # never delete what the book did not write
        raise ValueError(f"{src} exists and was not written by the book (it writes its sources there); move it or "
                         "choose another --out")
    check_packages()  # after the folders: a bad --out is named whatever is installed
    shutil.rmtree(src, ignore_errors=True)
    try:
        _write_sources(src, notebooks)
    except OSError as err:  # a copy's error names the notebook it copied: the device that is full is out's
        if err.errno in (errno.ENOSPC, errno.EDQUOT):
            raise OSError(err.errno, err.strerror, str(out)) from None
        raise
    cmd = [sys.executable, "-m", "sphinx", "-b", "html", "-E", *(["-q"] if quiet else []), str(src), str(out)]
    done = subprocess.run(cmd, stderr=subprocess.PIPE, text=True)
    if done.returncode:  # one line, not Sphinx's crash report (it keeps the report in a file it names)
        saved = re.search(r"saved in (\S+?)\.?$", done.stderr, re.M)
        where = f"; Sphinx's report: {saved.group(1)}" if saved else ""
        if "No space left on device" in done.stderr:
            raise OSError(errno.ENOSPC, f"Sphinx could not write the book{where}", str(out))
        last = (done.stderr.strip().splitlines() or ["no message"])[-1]
        raise ValueError(f"Sphinx failed to build the book into {out} (exit status {done.returncode}): {last}{where}")
    sys.stderr.write(done.stderr)  # its warnings
    return out / "index.html"


def _write_sources(src: Path, notebooks: Path) -> None:
    """The Sphinx sources of the book in ``src``: the notebooks, the glossary, the front page,
    the configuration and the static files."""
    (src / "notebooks").mkdir(parents=True)
    (src / SOURCES_MARK).write_text("the book's Sphinx sources, rewritten at every build\n")
    paths = notebook_paths() if notebooks == NOTEBOOKS else sorted(Path(notebooks).glob("[0-9]*.ipynb"))
    for path in paths:
        shutil.copy2(path, src / "notebooks" / path.name)
    shutil.copy2(ROOT / "GLOSSARY.md", src / "glossary.md")
    (src / "conf.py").write_text(CONF)
    (src / "index.md").write_text(index_page(overview_map(Path(notebooks) / f"{OVERVIEW}.ipynb"), paths))
    shutil.copytree(mathjax_dir(), src / "_static" / "mathjax")
    (src / "_static" / "favicon.svg").write_text(FAVICON)


def command_line() -> cli.Parser:
    """The command line of ``book``."""
    parser = cli.Parser(prog="python -m oapo_lite book", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default=str(ROOT / "build" / "book"),
                        help=cli.flag_help("folder of the built site", "build/book",
                                           "a new or empty folder, or the book's earlier build"))
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = command_line()
    args = parser.parse_args(argv)
    try:
        out = cli.output_folder(args.out, "--out")
    except ValueError as err:
        parser.error(str(err))
    index = build(out)
    print(f"book: {index}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
