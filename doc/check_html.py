"""Check the built HTML documentation for what a reader must never see.

Usage: ``python doc/check_html.py OUTDIR`` after ``sphinx-build -b html doc
OUTDIR``. Every ``*.html`` page under OUTDIR (``_static`` aside) is read, and
the script exits with status 1, listing each page, rule and snippet, when

``raw-tex``
    TeX appears as plain text, outside the containers that MathJax renders
    (elements of class ``math``) and outside code: ``\\(``, ``\\[``, ``$$``
    or a command such as ``\\frac`` or ``\\bigl``. The reader would see the
    source of a formula;
``math-without-mathjax``
    a page has math containers but does not load the MathJax bundled in the
    output (a local ``<script src>`` naming ``mathjax`` whose file exists);
``gallery-warning``
    the output of an example in the gallery (sphinx-gallery's
    ``sphx-glr-script-out`` blocks) contains the text ``Warning`` (as in
    ``ConvergenceWarning`` or ``UserWarning``);
``gallery-path``
    such an output contains a file path of the build machine (``/work/``,
    ``/home/``, ``/root/``, ``/tmp/``, ``site-packages``, the repository's
    or OUTDIR's absolute path);
``external-script``
    a ``<script src>`` loads from another host (a CDN): the page would not
    work without a network.
"""

import re
import sys
from collections import Counter
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

# TeX delimiters and commands (a backslash followed by letters). In plain text
# neither has any other use in these pages.
RAW_TEX = re.compile(r"\\[(\[]|\$\$|\\[A-Za-z]+")
MACHINE_PATHS = ("/work/", "/home/", "/root/", "/tmp/", "site-packages", "dist-packages")
# Elements whose text is code or not displayed: TeX there is not a formula.
CODE_TAGS = {"pre", "code", "kbd", "samp", "script", "style", "textarea"}
VOID_TAGS = {"area", "base", "br", "col", "embed", "hr", "img", "input", "link", "meta",
             "param", "source", "track", "wbr"}
SNIPPET_CONTEXT = 40


class _PageParser(HTMLParser):
    """Collects the text of a page with its context, and the script sources."""

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self._open = []  # (tag, classes) of the enclosing elements
        self.plain_text = []  # text outside math containers and code
        self.gallery_output = []  # text of the examples' output blocks
        self.has_math = False
        self.script_sources = []

    def handle_starttag(self, tag, attrs):
        attributes = dict(attrs)
        classes = set((attributes.get("class") or "").split())
        if tag == "script" and attributes.get("src"):
            self.script_sources.append(attributes["src"])
        if "math" in classes:
            self.has_math = True
        if tag not in VOID_TAGS:
            self._open.append((tag, classes))

    def handle_startendtag(self, tag, attrs):
        # A self-closed element encloses no text.
        self.handle_starttag(tag, attrs)
        if tag not in VOID_TAGS:
            self._open.pop()

    def handle_endtag(self, tag):
        # Close up to the matching element; HTML lets some end tags be implied.
        for depth in range(len(self._open) - 1, -1, -1):
            if self._open[depth][0] == tag:
                del self._open[depth:]
                return

    def handle_data(self, data):
        tags = {tag for tag, _ in self._open}
        classes = set().union(*(classes for _, classes in self._open))
        if "sphx-glr-script-out" in classes:
            self.gallery_output.append(data)
        elif "math" not in classes and not tags & CODE_TAGS:
            self.plain_text.append(data)


def _snippet(text, start, end):
    """The match with some context, on one line."""
    excerpt = text[max(0, start - SNIPPET_CONTEXT):end + SNIPPET_CONTEXT]
    return " ".join(excerpt.split())


def _path_tokens(machine_paths):
    """Pattern of the words (between spaces or quotes) holding one of the paths.

    A path that holds several of them (``/work/venv/.../site-packages``) is
    one match.
    """
    markers = "|".join(re.escape(path) for path in machine_paths)
    word = r"[^\s'\"()<>]*"
    return re.compile(f"{word}(?:{markers}){word}")


def _is_external(source):
    parts = urlsplit(source)
    return bool(parts.scheme or parts.netloc)


def _loads_local_mathjax(page, sources):
    """True when a local script of the page names mathjax and exists in the output."""
    for source in sources:
        if _is_external(source) or "mathjax" not in source.lower():
            continue
        if (page.parent / unquote(urlsplit(source).path)).is_file():
            return True
    return False


def check_page(page, machine_paths=MACHINE_PATHS):
    """Problems of one HTML page, as (rule, snippet) pairs.

    Parameters
    ----------
    page : pathlib.Path
        The HTML file; local script sources are resolved against its folder.
    machine_paths : sequence of str, default=MACHINE_PATHS
        Texts that reveal a file path of the build machine in an example's
        output.

    Returns
    -------
    problems : list of tuple of (str, str)
        The rule broken and a snippet of the offending text, in page order
        within each rule.
    """
    parser = _PageParser()
    parser.feed(page.read_text(encoding="utf-8"))
    parser.close()
    problems = []
    plain = "".join(parser.plain_text)
    for match in RAW_TEX.finditer(plain):
        problems.append(("raw-tex", _snippet(plain, match.start(), match.end())))
    if parser.has_math and not _loads_local_mathjax(page, parser.script_sources):
        problems.append(("math-without-mathjax",
                         "math containers, but no local MathJax script"))
    output = "".join(parser.gallery_output)
    for match in re.finditer("Warning", output):
        problems.append(("gallery-warning", _snippet(output, match.start(), match.end())))
    for match in _path_tokens(machine_paths).finditer(output):
        problems.append(("gallery-path", _snippet(output, match.start(), match.end())))
    for source in parser.script_sources:
        if _is_external(source):
            problems.append(("external-script", source))
    return problems


def check_site(outdir, machine_paths=MACHINE_PATHS):
    """Problems of every HTML page under ``outdir`` (``_static`` aside).

    Returns
    -------
    problems : list of tuple of (str, str, str)
        Page (relative to ``outdir``), rule and snippet.
    """
    outdir = Path(outdir)
    return [(page.relative_to(outdir).as_posix(), rule, snippet)
            for page in _pages(outdir)
            for rule, snippet in check_page(page, machine_paths)]


def _pages(outdir):
    """The HTML pages of the site; _static holds the theme's and MathJax's files."""
    return [page for page in sorted(outdir.rglob("*.html"))
            if page.relative_to(outdir).parts[0] != "_static"]


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1 or not Path(argv[0]).is_dir():
        print("usage: python doc/check_html.py OUTDIR (a built HTML site)", file=sys.stderr)
        return 2
    outdir = Path(argv[0])
    repository = str(Path(__file__).resolve().parents[1])
    machine_paths = (*MACHINE_PATHS, repository, str(outdir.resolve()))
    problems = check_site(outdir, machine_paths)
    n_pages = len(_pages(outdir))
    # A warning raised in a loop repeats the same snippet: list it once.
    counts = Counter(problems)
    for (page, rule, snippet), count in counts.items():
        print(f"{page}: {rule}: {snippet}" + (f" ({count} times)" if count > 1 else ""))
    if problems:
        n_bad = len({page for page, _, _ in problems})
        print(f"check_html: {len(problems)} problem(s) in {n_bad} of {n_pages} page(s).")
        return 1
    print(f"check_html: {n_pages} page(s), no problem.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
