"""The benchmarks' own modules (``benchmarks/``, not a package), loaded by path for the tests that use them."""

import importlib.util
from pathlib import Path


def load_benchmark_module(name: str):
    """``benchmarks/<name>.py`` as a module of its own (a peer such as ``_fcd``, or a helper such as ``_record``)."""
    path = Path(__file__).resolve().parents[1] / "benchmarks" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(f"benchmarks_{name}", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod
