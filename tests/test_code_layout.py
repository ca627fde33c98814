"""The layering rule of the README's "Code layout": a module never imports a private name or module of another subpackage."""

import ast
from pathlib import Path

import pytest

import glassdist

SRC = Path(glassdist.__file__).parent
#: top-level private modules that serve the whole package (README, "Code layout")
SHARED = {"glassdist._version", "glassdist._cli_shared"}


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


#: Test helpers holding the truths the accuracy tests compare the analyzer with (docs/testing.md).
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
