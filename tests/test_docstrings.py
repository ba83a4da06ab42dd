"""Every public docstring documents exactly the parameters of its signature, in
order, and the Examples of every docstring of the package, private ones
included, run, print what they show and warn of nothing."""

import doctest
import importlib
import inspect
import warnings
from pathlib import Path

import pytest

docscrape = pytest.importorskip("numpydoc.docscrape")

PUBLIC_MODULES = ["sknlss", "sknlss.metrics", "sknlss.signals", "sknlss.datasets",
                  "sknlss.plotting", "sknlss.model_selection", "sknlss.benchmarks"]
# The command line's entry point, documented in the API reference.
COMMAND_LINE = {"sknlss.__main__": ["main"]}


def _public_objects():
    """(qualified name, callable) of every public function, class and method."""
    found = {}
    for module_name in PUBLIC_MODULES + list(COMMAND_LINE):
        module = importlib.import_module(module_name)
        for name in COMMAND_LINE.get(module_name, getattr(module, "__all__", [])):
            obj = getattr(module, name)
            found[f"{module_name}.{name}"] = obj
            if inspect.isclass(obj):
                for method_name, method in _own_public_methods(obj):
                    found[f"{module_name}.{name}.{method_name}"] = method
    return sorted(found.items())


def _own_public_methods(cls):
    """Public methods defined by sknlss (inherited ones included), not by scikit-learn."""
    seen = set()
    for klass in cls.__mro__:
        if not klass.__module__.startswith("sknlss"):
            continue
        for method_name, member in vars(klass).items():
            if method_name.startswith("_") or method_name in seen:
                continue
            if inspect.isfunction(member) or isinstance(member, (classmethod, staticmethod)):
                seen.add(method_name)
                yield method_name, getattr(cls, method_name)


def _signature_names(obj):
    """Parameter names as a docstring lists them: no self/cls, ``*args`` and ``**kwargs`` kept."""
    target = obj.__init__ if inspect.isclass(obj) else obj
    names = []
    for parameter in inspect.signature(target).parameters.values():
        if parameter.name in ("self", "cls"):
            continue
        prefix = {inspect.Parameter.VAR_POSITIONAL: "*",
                  inspect.Parameter.VAR_KEYWORD: "**"}.get(parameter.kind, "")
        names.append(prefix + parameter.name)
    return names


def _documented_names(obj):
    """Names in the numpydoc Parameters section; ``a, b : float`` counts as two.

    A class documents its constructor's parameters in the class docstring.
    """
    parsed = docscrape.NumpyDocString(inspect.getdoc(obj) or "")
    names = []
    for parameter in parsed["Parameters"]:
        names.extend(part.strip() for part in parameter.name.split(","))
    return names


def _normalise_star(names):
    """Compare ``*args`` and ``args`` alike: both spellings are numpydoc conventions."""
    return [name.lstrip("*") for name in names]


def _has_own_init(cls):
    """True when sknlss defines the constructor (not e.g. a builtin exception's)."""
    return any(
        "__init__" in vars(klass) and klass.__module__.startswith("sknlss")
        for klass in cls.__mro__
    )


OBJECTS = _public_objects()


def test_public_names_are_found():
    names = {qualified for qualified, _ in OBJECTS}
    for estimator in ("BLAEstimator", "PNLSSRegressor", "NLSS2Regressor", "DecoupledPNLSS"):
        assert f"sknlss.{estimator}" in names
    assert "sknlss.metrics.rms_error" in names
    assert "sknlss.plotting.plot_frf" in names


def test_checker_detects_mismatches():
    def documented(a, b, *args, c=1, **kwargs):
        """Summary.

        Parameters
        ----------
        a, b : int
            Two numbers.
        *args : tuple
            More.
        d : int
            Misnamed.
        **kwargs : dict
            Options.
        """

    assert _normalise_star(_signature_names(documented)) == ["a", "b", "args", "c", "kwargs"]
    assert _normalise_star(_documented_names(documented)) == ["a", "b", "args", "d", "kwargs"]


@pytest.mark.parametrize("qualified, obj", OBJECTS, ids=[name for name, _ in OBJECTS])
def test_parameters_section_matches_signature(qualified, obj):
    docstring = inspect.getdoc(obj)
    assert docstring, f"{qualified} has no docstring"
    if inspect.isclass(obj) and not _has_own_init(obj):
        return
    expected = _normalise_star(_signature_names(obj))
    documented = _normalise_star(_documented_names(obj))
    assert documented == expected, (
        f"{qualified}: the Parameters section lists {documented}, the signature has {expected}"
    )


def _package_modules():
    """Every module of the package, private ones included (their folders are
    namespace packages, which ``pkgutil`` does not walk)."""
    root = Path(importlib.import_module("sknlss").__file__).parent
    for path in sorted(root.rglob("*.py")):
        parts = path.relative_to(root.parent).with_suffix("").parts
        if parts[-1] == "__main__":
            continue
        yield importlib.import_module(".".join(parts[:-1] if parts[-1] == "__init__" else parts))


def _example_tests():
    """The doctests of every docstring of the package, private ones included,
    each found once (in the module that defines it)."""
    finder, found = doctest.DocTestFinder(), {}
    for module in _package_modules():
        for test in finder.find(module, module.__name__, globs={}):
            # The docstrings of decorated functions have no line number.
            if test.examples and test.filename == module.__file__:
                found.setdefault((test.filename, test.lineno or test.name), test)
    return sorted(found.values(), key=lambda test: test.name)


EXAMPLES = _example_tests()


def test_examples_are_found():
    names = {test.name for test in EXAMPLES}
    assert {"sknlss._estimators._pnlss.PNLSSRegressor",
            "sknlss._estimators._nllfr.NLLFRRegressor",
            "sknlss._terms._polynomial.monomial_exponents"} <= names


@pytest.mark.parametrize("test", EXAMPLES, ids=[test.name for test in EXAMPLES])
def test_examples_run(test):
    pytest.importorskip("matplotlib").use("Agg")
    report = []
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    # An example that warns shows users a fit that needs other settings.
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = runner.run(test, out=report.append)
    assert result.failed == 0, "".join(report)
    # Deprecations come from the dependencies' versions, not from the example.
    shown = [w for w in caught if not issubclass(
        w.category, (DeprecationWarning, PendingDeprecationWarning, FutureWarning))]
    assert not shown, [f"{w.category.__name__}: {w.message}" for w in shown]


def test_api_reference_lists_every_public_name():
    api = Path(__file__).resolve().parents[1] / "doc" / "api.rst"
    if not api.is_file():
        pytest.skip("doc/api.rst is not part of this installation")
    listed = set()
    module = None
    for line in api.read_text(encoding="utf-8").splitlines():
        stripped = line.strip()
        if stripped.startswith(".. currentmodule::"):
            module = stripped.split("::")[1].strip()
        elif module and stripped.isidentifier() and line.startswith("   "):
            listed.add(f"{module}.{stripped}")
    missing = []
    for module_name in PUBLIC_MODULES:
        for name in importlib.import_module(module_name).__all__:
            if f"{module_name}.{name}" not in listed:
                missing.append(f"{module_name}.{name}")
    assert not missing, f"public names missing from doc/api.rst: {missing}"
