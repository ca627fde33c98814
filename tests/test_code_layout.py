"""The layering rule of the README's "Code layout": a module never imports a private name or module of another subpackage."""

import ast
from pathlib import Path

import pytest

import glassdist

SRC = Path(glassdist.__file__).parent
#: top-level private modules that serve the whole package (README, "Code layout")
SHARED = {"glassdist._version", "glassdist._cli_shared", "glassdist._lazy"}


def _subpackage(module: str) -> str:
    """The subpackage a dotted name lives in ("" for the top-level modules)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and (SRC / parts[1]).is_dir() else ""


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _imports(path: Path):
    """``(imported module, imported name or None)`` for every import of the module at ``path``."""
    module = "glassdist." + ".".join(path.relative_to(SRC).with_suffix("").parts)
    package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
    package = package.removesuffix(".__init__")
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            base = package.split(".")
            target = ".".join(base[: len(base) - node.level + 1] + ([node.module] if node.module else [])) \
                if node.level else (node.module or "")
            for alias in node.names:
                yield module, target, alias.name
        elif isinstance(node, ast.Import):
            for alias in node.names:
                yield module, alias.name, None


def _violations():
    out = []
    for path in sorted(SRC.rglob("*.py")):
        for module, target, name in _imports(path):
            if not target.startswith("glassdist") or target in SHARED:
                continue
            here, there = _subpackage(module), _subpackage(target)
            if here == there:
                continue
            private_module = any(_private(p) for p in target.split(".")[1:])
            private_name = name is not None and _private(name) and f"{target}.{name}" not in SHARED
            if private_module or private_name:
                out.append(f"{module} imports {target}{'.' + name if name else ''}")
    return out


def test_no_module_imports_a_private_name_of_another_subpackage():
    assert _violations() == []


@pytest.mark.parametrize("sub", sorted(p.parent.name for p in SRC.glob("*/__init__.py")))
def test_every_subpackage_declares_its_public_api(sub):
    tree = ast.parse((SRC / sub / "__init__.py").read_text())
    names = [t.id for n in tree.body if isinstance(n, ast.Assign) for t in n.targets if isinstance(t, ast.Name)]
    assert "__all__" in names


#: Test helpers holding the truths the accuracy tests compare the analyzer with (docs/validation/testing.md).
TRUTH_HELPERS = [Path(__file__).parent / "_truth.py"]


@pytest.mark.parametrize("path", TRUTH_HELPERS, ids=lambda p: p.name)
def test_truth_helpers_import_nothing_from_glassdist(path):
    """An independent truth cannot share code with what it checks: no import of glassdist at all."""
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and not node.level:
            names = [node.module or ""]
        elif isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", "")) in (
                "import_module", "__import__"):
            names = [a.value for a in node.args if isinstance(a, ast.Constant) and isinstance(a.value, str)]
        else:
            continue
        found += [n for n in names if n == "glassdist" or n.startswith("glassdist.")]
    assert found == [], f"{path.name} imports {found}"


def test_round_trip_truth_is_the_independent_helper():
    """``conftest.truth_channels`` evaluates the truth with ``_truth``, not the analyzer's stack."""
    tree = ast.parse((Path(__file__).parent / "conftest.py").read_text())
    fn = next(n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name == "truth_channels")
    modules = {n.module for n in ast.walk(fn) if isinstance(n, ast.ImportFrom)}
    modules |= {a.name for n in ast.walk(fn) if isinstance(n, ast.Import) for a in n.names}
    assert modules == {"_truth"}, modules


def _module_name(path: Path) -> str:
    parts = ("glassdist", *path.relative_to(SRC).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _import_graph(*, deferred: bool) -> dict[str, set[str]]:
    """``{module: modules of glassdist it imports}``, from the source (AST); ``deferred``: also imports inside functions.

    ``from package import name`` counts as an import of the module ``package.name`` when
    there is one, else of ``package``; a module's own ancestor packages (always imported
    before it) are left out.
    """
    modules = {_module_name(p): p for p in SRC.rglob("*.py")}
    graph = {}
    for module, path in modules.items():
        package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
        tree = ast.parse(path.read_text())
        nodes = ast.walk(tree) if deferred else _top_level_imports(tree.body)
        deps = set()
        for node in nodes:
            if isinstance(node, ast.ImportFrom):
                base = package.split(".")
                target = ".".join(base[: len(base) - node.level + 1] + ([node.module] if node.module else [])) \
                    if node.level else (node.module or "")
                found = [f"{target}.{a.name}" if f"{target}.{a.name}" in modules else target for a in node.names]
            elif isinstance(node, ast.Import):
                found = [a.name for a in node.names]
            else:
                continue
            deps |= {m for m in found if m in modules and m != module and not module.startswith(m + ".")}
        graph[module] = deps
    return graph


def _top_level_imports(body):
    """Import statements run when the module is imported (not those inside functions or classes)."""
    for node in body:
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node
        elif isinstance(node, (ast.If, ast.Try, ast.With)):
            for field in ("body", "orelse", "finalbody", "handlers"):
                yield from _top_level_imports(getattr(node, field, []))
        elif isinstance(node, ast.ExceptHandler):
            yield from _top_level_imports(node.body)


def _cycles(graph) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_cycle_finder_finds_a_cycle():
    """The check below can fail: a two-module loop and a three-module loop are found, a chain is not."""
    graph = {"a": {"b"}, "b": {"a"}, "c": {"d"}, "d": {"e"}, "e": {"c"}, "f": {"a"}}
    assert sorted(_cycles(graph)) == [["a", "b"], ["c", "d", "e"]]
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": set()}) == []


def test_no_import_cycle_when_modules_are_imported():
    """No two modules of glassdist import each other, directly or through others, at import time."""
    assert _cycles(_import_graph(deferred=False)) == []


def test_no_import_cycle_even_through_deferred_imports():
    """Counting the imports inside functions too, no two modules of glassdist import each other."""
    assert _cycles(_import_graph(deferred=True)) == []


#: the output floor, lowest layer first: a module may import its own layer and those below, never one above
OUTPUT_FLOOR = (
    ("leaves", ("glassdist.fs", "glassdist.io", "glassdist.errors", "glassdist.validation")),
    ("acceptance", ("glassdist.acceptance", "glassdist.measures")),
    ("rendering", ("glassdist.report",)),
    ("history", ("glassdist.history",)),
    ("storage", ("glassdist.storage",)),
    ("jobs", ("glassdist.jobs",)),
    ("entry points", ("glassdist.cli", "glassdist._api", "glassdist.web", "glassdist.virtual.sweep",
                      "glassdist._childserver")),
)


def _layer(module: str):
    for rank, (_, prefixes) in enumerate(OUTPUT_FLOOR):
        if any(module == p or module.startswith(p + ".") for p in prefixes):
            return rank
    return None


def _layering_violations(graph):
    out = []
    for module, deps in graph.items():
        here = _layer(module)
        if here is None:
            continue
        for dep in deps:
            there = _layer(dep)
            if there is not None and there > here:
                out.append(f"{module} ({OUTPUT_FLOOR[here][0]}) imports {dep} ({OUTPUT_FLOOR[there][0]})")
    return sorted(out)


def test_output_floor_is_layered():
    """Leaves < acceptance and measures < rendering < history < storage < jobs < entry points, deferred imports included."""
    assert _layering_violations(_import_graph(deferred=True)) == []


def _folder(module: str) -> str:
    """The folder node of a module: its subpackage (``glassdist.history``), or the top-level module itself."""
    parts = module.split(".")
    return ".".join(parts[:2]) if len(parts) > 1 and (SRC / parts[1]).is_dir() else module


def _folder_graph(graph) -> dict[str, set[str]]:
    """``{folder: folders it imports}`` from the module graph: a subpackage is one node, each top-level module one."""
    out: dict[str, set[str]] = {}
    for module, deps in graph.items():
        here = _folder(module)
        out.setdefault(here, set()).update(d for d in map(_folder, deps) if d != here)
    for deps in list(out.values()):
        for d in deps:
            out.setdefault(d, set())
    return out


def test_no_import_cycle_between_folders():
    """No two subpackages (or top-level modules) import each other, directly or through others, deferred imports
    included: each shared helper has one home in the lower folder."""
    assert _cycles(_folder_graph(_import_graph(deferred=True))) == []


def test_folder_graph_finds_a_loop_through_three_folders():
    graph = {"glassdist.history._cli": {"glassdist.jobs.batch"}, "glassdist.jobs.batch": {"glassdist.storage"},
             "glassdist.storage": set(), "glassdist.storage.writer": {"glassdist.history"}, "glassdist.history": set(),
             "glassdist.jobs.runner": {"glassdist.storage.writer"}}
    assert _cycles(_folder_graph(graph)) == [["glassdist.history", "glassdist.jobs", "glassdist.storage"]]
    del graph["glassdist.history._cli"]
    assert _cycles(_folder_graph(graph)) == []


def test_importing_glassdist_loads_no_subpackage_and_history_is_one_callable_object():
    """``import glassdist`` loads none of its subpackages; ``glassdist.history`` is the subpackage whichever way it is
    reached, and calling it reads the runs."""
    import subprocess
    import sys

    code = ("import sys, glassdist\n"
            "loaded = sorted(m for m in sys.modules if m.startswith('glassdist.') and m.count('.') == 1 "
            "and m not in ('glassdist._lazy', 'glassdist._version'))\n"
            "assert loaded == [], loaded\n"
            "h = glassdist.history\n"
            "import glassdist.history.store as store\n"
            "from glassdist import history\n"
            "assert h is history is glassdist.history and callable(h) and store.__name__ == 'glassdist.history.store'\n"
            "assert glassdist.history(db='off-by-path-none.sqlite', as_frame=False) == []\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=SRC.parent)
    assert proc.returncode == 0, proc.stderr


def test_layering_check_finds_an_upward_import():
    graph = {"glassdist.report.maps": {"glassdist.storage.writer"}, "glassdist.storage.writer": {"glassdist.report.maps"}}
    assert _layering_violations(graph) == ["glassdist.report.maps (rendering) imports glassdist.storage.writer (storage)"]


@pytest.mark.parametrize("path", sorted(p for sub in ("acceptance", "storage", "report", "jobs", "analyzer")
                                        for p in (SRC / sub).glob("*.py"))
                         + [SRC / "fs.py", SRC / "io.py", SRC / "measures.py", SRC / "cli.py", SRC / "_api.py"],
                         ids=lambda p: str(p.relative_to(SRC)))
def test_output_floor_modules_stay_under_900_lines(path):
    assert len(path.read_text().splitlines()) <= 900


def test_the_analyzer_pipeline_is_an_orchestrator():
    """pipeline.py keeps the inputs, the straight sequence of stages and the public API; the stages live in their modules."""
    assert len((SRC / "analyzer" / "pipeline.py").read_text().splitlines()) <= 600


#: The longest function body (its docstring, the contract, not counted) an analyzer module may hold.
MAX_FUNCTION_LINES = 80


def _long_functions(path: Path, limit: int = MAX_FUNCTION_LINES) -> list[str]:
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            body = node.body
            signature = body[0].lineno - node.lineno  # the def line(s) and decorators' own lines excluded
            if body and isinstance(body[0], ast.Expr) and isinstance(getattr(body[0], "value", None), ast.Constant) \
                    and isinstance(body[0].value.value, str):
                body = body[1:]
            lines = 0 if not body else body[-1].end_lineno - body[0].lineno + 1
            lines += signature
            if lines > limit:
                out.append(f"{path.name}:{node.lineno} {node.name} ({lines} lines)")
    return out


def test_no_analyzer_function_is_over_80_lines():
    found = [f for path in sorted((SRC / "analyzer").glob("*.py")) for f in _long_functions(path)]
    assert found == []


def test_the_function_length_check_finds_a_long_function(tmp_path):
    long = tmp_path / "long.py"
    long.write_text('def f():\n    """Doc."""\n' + "    x = 1\n" * 81)
    assert _long_functions(long) == ["long.py:1 f (82 lines)"]


@pytest.mark.parametrize("package", ["glassdist", *sorted(f"glassdist.{p.parent.name}" for p in SRC.glob("*/__init__.py"))])
def test_every_public_name_resolves(package):
    """A package's names may load on first use (``_lazy``): each one in ``__all__`` must still be there."""
    import importlib

    mod = importlib.import_module(package)
    missing = [n for n in mod.__all__ if n not in dir(mod)]
    broken = []
    for n in mod.__all__:
        try:
            getattr(mod, n)
        except AttributeError:
            broken.append(n)
    assert missing == [] and broken == [], (missing, broken)


def _typed_names(init: Path) -> dict[str, str]:
    """``{public name: ".module"}`` (``".module:attr"`` for an alias) imported under ``if TYPE_CHECKING:``."""
    tree = ast.parse(init.read_text())
    found: dict[str, str] = {}
    for node in tree.body:
        if isinstance(node, ast.If) and isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING":
            for imp in node.body:
                assert isinstance(imp, ast.ImportFrom), ast.dump(imp)
                module = "." * imp.level + (imp.module or "")
                for a in imp.names:
                    found[a.asname or a.name] = module if a.asname in (None, a.name) else f"{module}:{a.name}"
    return found


@pytest.mark.parametrize("init", sorted(p for p in SRC.rglob("__init__.py") if "lazy_exports(" in p.read_text()),
                         ids=lambda p: str(p.parent.relative_to(SRC.parent)))
def test_lazy_names_are_visible_to_static_tools(init):
    """What an IDE and mypy see (the TYPE_CHECKING imports) is exactly what ``__getattr__`` loads."""
    import importlib

    package = importlib.import_module(".".join(init.parent.relative_to(SRC.parent).parts))
    assert _typed_names(init) == package._LAZY_HOMES, "run: python scripts/lazy_stubs.py"
