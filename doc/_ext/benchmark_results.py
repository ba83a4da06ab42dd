"""The ``benchmark-result`` directive: a result file written by a benchmark script.

Benchmark figures are never typed into the documentation: the scripts in
``benchmarks/`` write them to ``doc/_generated/`` and the pages include the
files. A result that has not been generated yet (as in a fresh checkout) is
shown as a one-line note naming the command that writes it, instead of failing
the build::

    .. benchmark-result:: _generated/bench_accuracy.csv
       :command: python benchmarks/bench_accuracy.py
       :caption: Test RMS errors

The path is relative to the page, as for ``csv-table``. A ``.csv`` file
becomes a table whose first row is the header, a ``.png`` file a figure, any
other file a literal block.
"""

from pathlib import Path

from docutils.parsers.rst import directives
from sphinx.util.docutils import SphinxDirective


class BenchmarkResult(SphinxDirective):
    """Include a benchmark's result file, or say which command writes it."""

    required_arguments = 1
    option_spec = {
        "command": directives.unchanged_required,
        "caption": directives.unchanged,
    }

    def run(self):
        path = self.arguments[0]
        if "command" not in self.options:
            raise self.error("benchmark-result needs the :command: that writes the file.")
        _, absolute = self.env.relfn2path(path, self.env.docname)
        # A missing file is a dependency too: the page is rebuilt once it exists.
        self.env.note_dependency(absolute)
        if not Path(absolute).is_file():
            return self.parse_text_to_nodes(
                f"*Not generated yet:* run ``{self.options['command']}``."
            )
        # A caption written over several lines becomes one line of the directive.
        caption = " ".join(self.options.get("caption", "").split())
        suffix = Path(path).suffix.lower()
        if suffix == ".csv":
            # The rows go in as the table's content: a :file: option would be
            # resolved against the working folder when the text is parsed here.
            rows = Path(absolute).read_text(encoding="utf-8").splitlines()
            text = (f".. csv-table:: {caption}\n   :header-rows: 1\n\n"
                    + "".join(f"   {row}\n" for row in rows if row.strip()))
        elif suffix == ".png":
            text = f".. figure:: {path}\n\n   {caption}\n"
        else:
            text = f".. literalinclude:: {path}\n   :language: none\n"
            if caption:
                text += f"   :caption: {caption}\n"
        return self.parse_text_to_nodes(text)


def setup(app):
    app.add_directive("benchmark-result", BenchmarkResult)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
