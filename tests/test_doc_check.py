"""doc/check_html.py on hand-made pages: each rule fires on its case and only there."""

import importlib.util
from pathlib import Path

import pytest

_SCRIPT = Path(__file__).resolve().parents[1] / "doc" / "check_html.py"
if not _SCRIPT.is_file():
    pytest.skip("doc/check_html.py is not part of this installation", allow_module_level=True)
_spec = importlib.util.spec_from_file_location("check_html", _SCRIPT)
check_html = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(check_html)

MATHJAX = '<script defer="defer" src="_static/mathjax/tex-chtml.js"></script>'


def _page(body, head=MATHJAX):
    return f"<!DOCTYPE html><html><head>{head}</head><body>{body}</body></html>"


@pytest.fixture
def site(tmp_path):
    """An output folder with the bundled MathJax in _static."""
    mathjax = tmp_path / "_static" / "mathjax" / "tex-chtml.js"
    mathjax.parent.mkdir(parents=True)
    mathjax.write_text("// MathJax")

    def write(name, html):
        page = tmp_path / name
        page.parent.mkdir(parents=True, exist_ok=True)
        page.write_text(html, encoding="utf-8")
        return page

    write.root = tmp_path
    return write


def _rules(page, **kwargs):
    return [rule for rule, _ in check_html.check_page(page, **kwargs)]


def test_rendered_math_and_tex_in_code_pass(site):
    page = site("ok.html", _page(
        '<p>The state <span class="math notranslate nohighlight">\\(x(t)\\)</span>.</p>'
        '<div class="math notranslate nohighlight">\\[x(t+1) = f\\bigl(x(t)\\bigr)\\]</div>'
        '<pre>pattern = re.compile(r"\\(\\frac")</pre>'
        '<p>Escape with <code class="literal">\\alpha</code>; it costs $5.</p>'
    ))
    assert check_html.check_page(page) == []


@pytest.mark.parametrize("text", [
    "the model \\(x(t)\\) is", "\\[ y = Cx \\]", "$$y = Cx$$", "a \\frac{1}{2} step",
    "f\\bigl(x\\bigr)",
])
def test_raw_tex_in_plain_text_is_reported(site, text):
    page = site("raw.html", _page(f"<section><p>{text}</p></section>"))
    problems = check_html.check_page(page)
    assert problems and {rule for rule, _ in problems} == {"raw-tex"}
    assert problems[0][1] == text


def test_raw_tex_in_navigation_is_reported(site):
    # Text outside the math containers, e.g. a sidebar entry, is not rendered.
    page = site("nav.html", _page('<nav><a href="#">Cost \\(V(\\theta)\\)</a></nav>'))
    assert _rules(page)[:1] == ["raw-tex"]


def test_math_needs_the_local_mathjax(site):
    body = '<span class="math notranslate nohighlight">\\(x\\)</span>'
    assert _rules(site("cdn.html", _page(
        body, head='<script src="https://cdn.example.org/mathjax/tex-chtml.js"></script>'
    ))) == ["math-without-mathjax", "external-script"]
    assert _rules(site("none.html", _page(body, head=""))) == ["math-without-mathjax"]
    # The script must exist in the output: a page one folder down refers to ../_static.
    assert _rules(site("sub/missing.html", _page(body))) == ["math-without-mathjax"]
    nested = _page(body, head=MATHJAX.replace("_static", "../_static"))
    assert _rules(site("sub/found.html", nested)) == []


def test_pages_without_math_need_no_mathjax(site):
    assert _rules(site("plain.html", _page("<p>No formula.</p>", head=""))) == []


def _gallery_output(text):
    return _page(
        '<div class="highlight-Python"><pre>warnings.filterwarnings("ignore", '
        'category=ConvergenceWarning)</pre></div>'
        '<div class="sphx-glr-script-out highlight-none notranslate">'
        f'<div class="highlight"><pre><span></span>{text}\n</pre></div></div>'
    )


def test_warnings_in_gallery_output_are_reported(site):
    page = site("example.html", _gallery_output(
        "sknlss/_optimize.py:120: ConvergenceWarning: the iteration limit was reached"
    ))
    ((rule, snippet),) = check_html.check_page(page)
    assert rule == "gallery-warning"
    assert "ConvergenceWarning: the iteration limit" in snippet
    # In the example's code, outside its output, the name is fine; lower case too.
    assert _rules(site("clean.html", _gallery_output("no warning here"))) == []


@pytest.mark.parametrize("path", [
    "/work/shared/data/cascaded_tanks/dataBenchmark.mat",
    "/home/someone/data.csv",
    "/tmp/tmpabc/out.png",
    "/usr/lib/python3/site-packages/numpy/core.py",
])
def test_machine_paths_in_gallery_output_are_reported(site, path):
    page = site("paths.html", _gallery_output(f"Measured data from {path}"))
    assert _rules(page) == ["gallery-path"]


def test_a_path_is_reported_once(site):
    page = site("once.html", _gallery_output(
        "/work/venv/lib/python3.11/site-packages/sklearn/utils/parallel.py:184: note"
    ))
    problems = check_html.check_page(page, machine_paths=("/work/venv", "/work/",
                                                           "site-packages"))
    assert problems == [("gallery-path", "/work/venv/lib/python3.11/site-packages/"
                                         "sklearn/utils/parallel.py:184: note")]


def test_extra_machine_paths(site):
    page = site("repo.html", _gallery_output("Read /srv/build/sknlss/doc/conf.py"))
    assert _rules(page) == []
    assert _rules(page, machine_paths=("/srv/build/sknlss",)) == ["gallery-path"]


@pytest.mark.parametrize("source, external", [
    ("https://cdn.jsdelivr.net/npm/mathjax@3/es5/tex-mml-chtml.js", True),
    ("//cdnjs.cloudflare.com/ajax/libs/require.js/2.3.4/require.min.js", True),
    ("_static/documentation_options.js?v=5929fcd5", False),
    ("../_static/scripts/bootstrap.js", False),
])
def test_external_scripts_are_reported(site, source, external):
    page = site("scripts.html", _page("<p>Text.</p>", head=f'<script src="{source}"></script>'))
    assert _rules(page) == (["external-script"] if external else [])


def test_main_lists_page_rule_and_snippet_and_exits_non_zero(site, capsys):
    site("index.html", _page("<p>Fine.</p>"))
    # The same warning twice (from a loop) is listed once, with its count.
    site("auto_examples/plot_x.html", _gallery_output("UserWarning: careful\n" * 2))
    site("_static/ignored.html", _page("<p>\\frac</p>"))
    assert check_html.main([str(site.root)]) == 1
    out = capsys.readouterr().out.splitlines()
    assert out[0] == ("auto_examples/plot_x.html: gallery-warning: "
                      "UserWarning: careful UserWarning: careful (2 times)")
    assert out[-1] == "check_html: 2 problem(s) in 1 of 2 page(s)."


def test_main_passes_a_clean_site(site, capsys):
    site("index.html", _page('<p><span class="math">\\(x\\)</span></p>'))
    assert check_html.main([str(site.root)]) == 0
    assert "no problem" in capsys.readouterr().out


def test_main_usage(tmp_path, capsys):
    assert check_html.main([str(tmp_path / "absent")]) == 2
    assert "usage" in capsys.readouterr().err
