"""Packaging: the console script, --version from one place, every imported package declared in pyproject.toml."""

import ast
import functools
import importlib.metadata
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import sparsedepth as sd
from sparsedepth.complete import main

REPO = Path(__file__).resolve().parents[1]
PACKAGE = REPO / "sparsedepth"
OPTIONAL = ("matplotlib", "dask", "distributed", "tqdm")


def _pyproject():
    tomllib = pytest.importorskip("tomllib", reason="tomllib is in the standard library from Python 3.11")
    with open(REPO / "pyproject.toml", "rb") as fh:
        return tomllib.load(fh)


def _requirement_name(requirement: str) -> str:
    """The normalised distribution name of a requirement string (PEP 503)."""
    name = re.match(r"\s*([A-Za-z0-9][A-Za-z0-9._-]*)", requirement).group(1)
    return re.sub(r"[-_.]+", "-", name).lower()


@functools.cache
def _imports():
    """{top-level module: [(file, line, inside a function)]} of every absolute import in the package."""
    found = {}

    def visit(node, path, in_function):
        for child in ast.iter_child_nodes(node):
            nested = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            if isinstance(child, ast.Import):
                names = [alias.name for alias in child.names]
            elif isinstance(child, ast.ImportFrom) and child.level == 0:
                names = [child.module]
            else:
                names = []
            for name in names:
                found.setdefault(name.split(".")[0], []).append((path.relative_to(REPO), child.lineno, in_function))
            visit(child, path, nested)

    for path in sorted(PACKAGE.rglob("*.py")):
        visit(ast.parse(path.read_text(), str(path)), path, False)
    return found


@functools.cache
def _packages_distributions():
    """importlib.metadata.packages_distributions(), read once (it scans every installed distribution)."""
    return importlib.metadata.packages_distributions()


def _distributions(module: str) -> set[str]:
    """Distributions that provide ``module`` where it is installed; its own name otherwise."""
    names = _packages_distributions().get(module) or [module]
    return {re.sub(r"[-_.]+", "-", n).lower() for n in names}


def test_every_third_party_import_is_declared():
    project = _pyproject()["project"]
    required = {_requirement_name(r) for r in project["dependencies"]}
    extras = {_requirement_name(r) for group in project["optional-dependencies"].values() for r in group}
    imports = _imports()
    third_party = {m: where for m, where in imports.items()
                   if m not in sys.stdlib_module_names and m != "sparsedepth"}
    assert {"numpy", "scipy", "pyamg", "skimage", "h5py", "tifffile", "imageio", "PIL"} <= set(third_party)
    for module, where in third_party.items():
        distributions = _distributions(module)
        if distributions & required:
            continue
        assert distributions & extras, f"{module} (imported at {where[0][0]}:{where[0][1]}) is not declared"
        eager = [(str(path), line) for path, line, lazy in where if not lazy]
        assert not eager, f"optional {module} is imported when the module loads: {eager}"
    for module in OPTIONAL:
        assert not _distributions(module) & required, f"{module} must stay an optional extra"


def test_the_grep_of_imports_sees_lazy_and_eager_imports():
    imports = _imports()
    assert all(not lazy for _, _, lazy in imports["numpy"][:1])  # io modules import numpy at the top
    assert imports["tqdm"] and all(lazy for _, _, lazy in imports["tqdm"])
    assert imports["matplotlib"] and all(lazy for _, _, lazy in imports["matplotlib"])


def test_version_has_one_source():
    pyproject = _pyproject()
    assert "version" not in pyproject["project"] and "version" in pyproject["project"]["dynamic"]
    assert pyproject["tool"]["setuptools"]["dynamic"]["version"] == {"attr": "sparsedepth.__version__"}
    assignments = [path for path in PACKAGE.rglob("*.py") if re.search(r"^__version__\s*=", path.read_text(), re.M)]
    assert assignments == [PACKAGE / "__init__.py"]
    assert re.fullmatch(r"\d+\.\d+\.\d+([.-]?\w+)?", sd.__version__)
    try:
        dist = importlib.metadata.distribution("sparsedepth")
        origin = dist.read_text("direct_url.json") or ""
    except importlib.metadata.PackageNotFoundError:
        origin = ""
    if str(REPO) in origin:  # installed from this checkout: the metadata says the same
        assert dist.version == sd.__version__


def test_version_option(capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out == f"sparsedepth {sd.__version__}\n"
    assert main(["--help"]) == 0
    assert "--version" in capsys.readouterr().out
    run = subprocess.run([sys.executable, "-m", "sparsedepth.complete", "--version"], cwd=REPO,
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0 and run.stdout == f"sparsedepth {sd.__version__}\n"


def test_console_script():
    pyproject = _pyproject()
    assert pyproject["project"]["scripts"] == {"sparsedepth": "sparsedepth.complete:main"}
    script = shutil.which("sparsedepth")
    if script is None:
        pytest.skip("no 'sparsedepth' script on PATH (pip install -e . puts it there)")
    run = subprocess.run([script, "--version"], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0 and run.stdout == f"sparsedepth {sd.__version__}\n", run.stderr
    script_help = subprocess.run([script, "--help"], capture_output=True, text=True, timeout=120)
    module_help = subprocess.run([sys.executable, "-m", "sparsedepth.complete", "--help"], cwd=REPO,
                                 capture_output=True, text=True, timeout=120)
    assert script_help.returncode == module_help.returncode == 0
    assert script_help.stdout == module_help.stdout
    bad = subprocess.run([script, "--keep-fraction", "2"], capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "--keep-fraction" in bad.stderr
