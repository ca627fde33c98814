"""The analyzer speaks of its parameters, the command line of its options (cli.option_words translates)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import glassdist

ANALYZER = Path(glassdist.__file__).parent / "analyzer"
#: ``--params`` names the parameter file where the command line reads it (params.load_params's ``option``)
KNOWN = {("params.py", "--params")}
_OPTION = re.compile(r"(?<![\w-])--[a-z][a-z-]+")


def _messages(path: Path):
    """String constants of a module that are not docstrings."""
    tree = ast.parse(path.read_text())
    docs = {id(n.body[0].value) for n in ast.walk(tree)
            if isinstance(n, (ast.Module, ast.FunctionDef, ast.ClassDef, ast.AsyncFunctionDef)) and n.body
            and isinstance(n.body[0], ast.Expr) and isinstance(n.body[0].value, ast.Constant)}
    for n in ast.walk(tree):
        if isinstance(n, ast.Constant) and isinstance(n.value, str) and id(n) not in docs:
            yield n.value


def test_analyzer_messages_name_no_command_line_option():
    found = sorted({(p.name, m) for p in ANALYZER.glob("*.py") for s in _messages(p) for m in _OPTION.findall(s)}
                   - KNOWN)
    assert found == []


def test_the_command_line_names_its_options():
    from glassdist.cli import option_words

    said = ("Direct Method with detrend degree 2: the result depends on N - mean |phi_eff| moves from 8.05 to 7.33 mD "
            "(-9%) with detrend_degree 3: a distortion ... - calibrate the lens "
            "(lens: calibrate_from_photo, calibration_from_camera_file) or use the Comparative Method")
    assert option_words(said) == (
        "Direct Method with detrend degree 2: the result depends on N - mean |phi_eff| moves from 8.05 to 7.33 mD "
        "(-9%) with --detrend-degree 3: a distortion ... - calibrate the lens (--lens-photo, --camera-file) or use "
        "the Comparative Method")
    assert option_words("use the Comparative Method (a reference photo)") == "use the Comparative Method (--reference)"
    assert option_words("pitch_mm (the printed grid pitch) must be positive") == \
        "pitch_mm (--pitch-mm, the printed grid pitch) must be positive"
