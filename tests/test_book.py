"""The book (``make book``) in a real headless Chromium: every page loads without console
errors, every image loads, and the math is typeset by the MathJax the site serves itself.

Needs book-requirements.txt and Debian's ``chromium`` and ``chromium-driver`` (``make test``
installs both); without them the test is skipped, except under CI, where it fails.
"""
import functools
import http.server
import os
import shutil
import tempfile
import threading
from pathlib import Path

import nbformat
import pytest

CHROMIUM, CHROMEDRIVER = shutil.which("chromium"), shutil.which("chromedriver")


def _missing() -> str | None:
    try:
        import mathjax  # noqa: F401
        import myst_nb  # noqa: F401
        import selenium  # noqa: F401
    except ImportError as err:
        return f"book-requirements.txt is not installed ({err})"
    if not (CHROMIUM and CHROMEDRIVER):
        return "Debian's chromium and chromium-driver are not installed"
    return None


class QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):
        pass


@pytest.fixture(scope="module")
def site():
    reason = _missing()
    if reason:
        if os.environ.get("CI"):
            pytest.fail(f"the book test must run in CI: {reason}")
        pytest.skip(reason)
    from oapo_lite.study.report.book import build

    with tempfile.TemporaryDirectory() as tmp:
        index = build(Path(tmp) / "book")
        handler = functools.partial(QuietHandler, directory=str(index.parent))
        server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
        threading.Thread(target=server.serve_forever, daemon=True).start()
        try:
            yield index.parent, f"http://127.0.0.1:{server.server_port}"
        finally:
            server.shutdown()
            server.server_close()


@pytest.fixture(scope="module")
def browser():
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    profile = tempfile.mkdtemp(prefix="oapo-book-chromium-")
    for flag in ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 f"--user-data-dir={profile}", "--window-size=1200,900"):
        options.add_argument(flag)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
    yield driver
    driver.quit()
    shutil.rmtree(profile, ignore_errors=True)


def _pages(root: Path) -> list[str]:
    return ["index.html", "glossary.html"] + sorted(f"notebooks/{p.name}" for p in (root / "notebooks").glob("*.html"))


def test_every_notebook_has_a_page_and_the_front_page_links_them(site):
    root, _ = site
    from oapo_lite.study.runs.reproduce import notebook_paths

    stems = [p.stem for p in notebook_paths()]
    assert sorted(p.stem for p in (root / "notebooks").glob("*.html")) == stems
    front = (root / "index.html").read_text()
    for stem in stems:
        assert f'href="notebooks/{stem}.html' in front
    assert 'href="glossary.html' in front and "K_{ij}" in (root / "glossary.html").read_text()
    pages = [(root / page).read_text() for page in _pages(root)]
    assert not [page for page in pages if "https://" in page and "<script" in page.split("https://")[0][-200:]]
    assert any('src="../_static/mathjax/tex-mml-chtml.js' in page for page in pages)  # no CDN


MATH_DONE = """
const done = arguments[arguments.length - 1];
if (!document.querySelector('script[src*="mathjax"]')) done(true);  // a page without math loads none
else {
const wait = () => (window.MathJax && MathJax.startup && MathJax.startup.promise)
    ? MathJax.startup.promise.then(() => done(true), () => done(false)) : setTimeout(wait, 50);
wait();
}
"""
IMAGES = """
return Array.from(document.images).map(i => [i.currentSrc || i.src, i.complete, i.naturalWidth]);
"""
MATH = """
const spans = Array.from(document.querySelectorAll('.math'));
return [spans.length, spans.filter(s => s.querySelector('mjx-container')).length,
        document.querySelectorAll('mjx-merror').length];
"""


def test_every_page_loads_cleanly_with_its_images_and_typeset_math(site, browser):
    root, url = site
    from oapo_lite.study.runs.reproduce import notebook_paths

    has_math = {p.stem for p in notebook_paths()
                if any("$" in c.source for c in nbformat.read(p, 4).cells if c.cell_type == "markdown")}
    assert has_math, "no notebook has math to check"
    browser.set_script_timeout(60)
    images_seen = 0
    for page in _pages(root):
        browser.get(f"{url}/{page}")
        browser.execute_script("document.querySelectorAll('img').forEach(i => i.loading = 'eager');")
        assert browser.execute_async_script(MATH_DONE), f"{page}: MathJax failed to start"
        browser.execute_async_script("""const done = arguments[arguments.length - 1];
            Promise.all(Array.from(document.images).map(i => i.decode().catch(() => null))).then(done);""")
        errors = [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
        assert not errors, f"{page}: console errors {errors}"
        images = browser.execute_script(IMAGES)
        broken = [src for src, complete, width in images if not (complete and width > 0)]
        assert not broken, f"{page}: images that did not load: {broken}"
        images_seen += len(images)
        n_math, typeset, math_errors = browser.execute_script(MATH)
        assert typeset == n_math and math_errors == 0, f"{page}: {typeset} of {n_math} formulas typeset, " \
                                                       f"{math_errors} MathJax errors"
        if Path(page).stem in has_math:
            assert n_math > 0, f"{page}: the notebook has math, the page none"
    # every figure output of the notebooks is an image on its page (and the theme's logo none)
    figures = sum(1 for p in notebook_paths() for c in nbformat.read(p, 4).cells if c.cell_type == "code"
                  for o in c.outputs if "image/png" in o.get("data", {}))
    assert images_seen >= figures > 0


def test_notebook_text_has_no_control_characters():
    """A control character in a markdown cell is a LaTeX command eaten by a Python string
    escape (\\frac -> form feed + "rac"); MathJax may still typeset what is left, wrongly."""
    from oapo_lite.study.runs.reproduce import notebook_paths

    for path in notebook_paths():
        for k, cell in enumerate(nbformat.read(path, as_version=4).cells):
            bad = sorted({repr(c) for c in cell.source if ord(c) < 32 and c != "\n"})
            assert not bad, f"{path.name} cell {k}: control characters {bad}"
