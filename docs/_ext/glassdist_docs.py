"""Pages of the site generated at build time from the code and the records.

Written into ``docs/_generated/`` (not committed) when the builder starts, and included by
the reference and validation pages:

* ``fields.md``: the result's field registry (:data:`glassdist.analyzer.result.FIELDS`);
* ``spec_schema.md``: the acceptance specification, from its pydantic models;
* ``scene_schema.md``: the scene file of the Virtual Pipeline, from its pydantic models;
* ``summary_keys.md``: the keys of ``summary.json``, from a run of the writer on a small
  synthetic capture;
* ``validation_*.md``: the accuracy, experiment, benchmark, uncertainty, performance and
  mutation tables, each made from its JSON record under ``docs/records/`` by the function
  that wrote the record's table (never copied by hand).
"""

from __future__ import annotations

import importlib
import json
import os
import re
import sys
import tempfile
import types
import typing
from pathlib import Path

DOCS = Path(__file__).resolve().parents[1]
ROOT = DOCS.parent
RECORDS = DOCS / "records"
OUT = DOCS / "_generated"

#: the line of a benchmark's markdown after which its notes are written by hand
NOTES_MARK = "<!-- notes: written by hand below this line"


def _record(name: str) -> dict:
    return json.loads((RECORDS / name).read_text())


def _bench(name: str):
    """A module of ``benchmarks/`` (they import their helpers from that folder)."""
    if str(ROOT / "benchmarks") not in sys.path:
        sys.path.insert(0, str(ROOT / "benchmarks"))
    return importlib.import_module(name)


def _cell(text) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def _demote(markdown: str, levels: int = 1) -> str:
    """Headings one level down, so that a generated document sits under the page's own title."""
    out, fenced = [], False
    for line in markdown.splitlines():
        if line.startswith("```"):
            fenced = not fenced
        if not fenced and line.startswith("#"):
            line = "#" * levels + line
        out.append(line)
    return "\n".join(out)


def _source(name: str) -> str:
    """Where a generated table comes from, said under it."""
    rec = _record(name)
    cmd = rec.get("command")
    line = f"*Generated from* `docs/records/{name}`"
    return line + (f", *written by* `{cmd}`." if cmd else ".")


_LINK = re.compile(r"\[([^\]]*)\]\(([^)#\s]+)(#[^)\s]*)?\)")


def _relinked(text: str, page_dir: Path) -> str:
    """Links of a record's notes (relative to ``docs/records/``) as links of the page that includes them.

    A link to another benchmark's markdown becomes a reference to that benchmark's section
    (its label is the record's name); any other relative link is re-rooted at ``page_dir``.
    """
    def sub(m):
        words, target, anchor = m.group(1), m.group(2), m.group(3) or ""
        if "://" in target:
            return m.group(0)
        if target.endswith(".md") and (RECORDS / target).with_suffix(".json").exists() and "/" not in target:
            return f"{{ref}}`{words.replace('`', '')} <{target[:-3]}>`"
        return f"[{words}]({os.path.relpath(RECORDS / target, page_dir)}{anchor})"

    return _LINK.sub(sub, text)


def _notes(md_name: str) -> str:
    """What follows the notes mark of a benchmark's markdown (the prose written by hand), or ''."""
    text = (RECORDS / md_name).read_text()
    if NOTES_MARK not in text:
        return ""
    return _relinked(text.split(NOTES_MARK, 1)[1].split("-->", 1)[1].strip(), DOCS / "validation")


# --- reference -------------------------------------------------------------------------------

def fields_page() -> str:
    from glassdist.analyzer.result import FIELDS

    lines = ["| name | unit | components | kind | meaning |", "|---|---|---|---|---|"]
    for f in FIELDS:
        lines.append(f"| `{f.name}` | {_cell(f.unit)} | {f.components} | {f.kind} | {_cell(f.description)} |")
    return "\n".join(lines) + "\n"


def _type_name(annotation) -> str:
    text = getattr(annotation, "__name__", None) if not typing.get_args(annotation) else None
    text = text or str(annotation)
    for prefix in ("typing.", "glassdist.acceptance.spec.", "glassdist.scene.model.", "glassdist.scene.surfaces.",
                   "pathlib."):
        text = text.replace(prefix, "")
    return text.replace("NoneType", "None")


def _models(root) -> list:
    """``root`` and every pydantic model reachable from its fields, in order of first use."""
    from pydantic import BaseModel

    seen, order = set(), []

    def visit(model):
        if model in seen:
            return
        seen.add(model)
        order.append(model)
        for f in model.model_fields.values():
            stack = [f.annotation]
            while stack:
                a = stack.pop()
                if isinstance(a, type) and issubclass(a, BaseModel):
                    visit(a)
                stack.extend(typing.get_args(a))

    visit(root)
    return order


def _default(value) -> str:
    from pydantic import BaseModel

    if isinstance(value, BaseModel):
        return json.dumps(value.model_dump(mode="json", by_alias=True))
    try:
        return json.dumps(value)
    except TypeError:
        return str(getattr(value, "value", value))


def _model_tables(root, heading: str) -> str:
    from pydantic_core import PydanticUndefined

    parts = []
    for model in _models(root):
        doc = (model.__doc__ or "").strip().split("\n\n")[0].replace("\n", " ")
        lines = [f"{heading} `{model.__name__}`", "", _cell(doc), "",
                 "| key | type | default | meaning |", "|---|---|---|---|"]
        for name, f in model.model_fields.items():
            key = f.alias or name
            if f.is_required():
                default = "required"
            elif f.default_factory is not None:
                default = "(empty)"
            elif f.default is PydanticUndefined:
                default = ""
            else:
                default = f"`{_cell(_default(f.default))}`"
            lines.append(f"| `{key}` | `{_cell(_type_name(f.annotation))}` | {default} | {_cell(f.description or '')} |")
        parts.append("\n".join(lines))
    return "\n\n".join(parts) + "\n"


def spec_schema_page() -> str:
    from glassdist.acceptance.spec import Spec

    return _model_tables(Spec, "##")


def scene_schema_page() -> str:
    from glassdist.scene.model import Scene

    return _model_tables(Scene, "##")


def summary_keys_page() -> str:
    """``summary.json`` of a real run (the writer on a small synthetic capture): each key, its type, an example."""
    import numpy as np

    import glassdist
    from glassdist.synthetic import synthetic_capture, wave_displacement

    capture = synthetic_capture((192, 256), pitch_mm=8.0, mm_per_px=1.0,
                                displacement=wave_displacement(0.3, 120.0), rng=0)
    with tempfile.TemporaryDirectory() as tmp:
        result = glassdist.analyze(capture.image, pitch_mm=8.0, distance_m=1.0, reference=capture.reference)
        glassdist.write_outputs(result, Path(tmp) / "run", history=False)
        summary = json.loads((Path(tmp) / "run" / "summary.json").read_text())

    def kind(v) -> str:
        if v is None:
            return "null"
        return {dict: "object", list: "array", str: "string", bool: "boolean", int: "integer",
                float: "number"}.get(type(v), type(v).__name__)

    def example(v) -> str:
        if isinstance(v, (dict, list)):
            return ""
        text = json.dumps(v if not isinstance(v, float) else float(np.round(v, 6)))
        return f"`{_cell(text[:60])}`"

    lines = ["| key | type | example (this run) |", "|---|---|---|"]

    def walk(d: dict, prefix: str, depth: int):
        for k, v in d.items():
            lines.append(f"| `{prefix}{k}` | {kind(v)} | {example(v)} |")
            if isinstance(v, dict) and depth < 1 and k != "outputs":
                walk(v, f"{prefix}{k}.", depth + 1)

    walk(summary, "", 0)
    return "\n".join(lines) + "\n"


# --- validation ------------------------------------------------------------------------------

def accuracy_page() -> str:
    from glassdist.experiments.accuracy import accuracy_markdown

    text = accuracy_markdown(_record("accuracy.json"))
    text = text.split("\n", 1)[1] if text.startswith("# ") else text  # the page has its own title
    return text + "\n"


def experiments_page() -> str:
    from glassdist.experiments.parity import parity_table
    from glassdist.experiments.pitch import pitch_table
    from glassdist.experiments.rotation import rotation_table
    from glassdist.experiments.transfer import transfer_table

    parts = []
    for name, title, fn in (("parity", "Parity (paper §3.1)", parity_table), ("pitch", "Pitch (paper §3.2)", pitch_table),
                            ("rotation", "Rotation (paper §3.3)", rotation_table),
                            ("transfer", "Transfer function, ripples and a large lens", transfer_table)):
        rec = f"experiments/{name}.json"
        parts.append(f"## {title}\n\n{_demote(fn(_record(rec)), 2)}\n\n{_source(rec)}")
    return "\n\n".join(parts) + "\n"


def benchmarks_page() -> str:
    ripples = _bench("bench_strong_ripples")
    peers = _bench("bench_waves_peers")
    truth = _bench("bench_displacement_truth")
    mirror = _bench("bench_growth_mirror")
    yard = _bench("bench_yardstick")

    def yardstick(rec):
        old = {(r["scene"], r["method"]): {k: v for k, v in r.items() if k not in ("scene", "method")}
               for r in rec["record"]}
        return yard.table(rec["rows"], old, rec["record_commit"])

    sections = [
        ("yardstick", "The accuracy yardstick", yardstick),
        ("strong_ripples", "Strong ripples (rendered)", lambda r: ripples.table(r["records"])),
        ("strong_ripples_photo", "Strong ripples, photo deformation passes", lambda r: ripples.table(r["records"])),
        ("strong_ripples_dome", "Strong ripples on a pillow dome", lambda r: ripples.table(r["records"])),
        ("strong_ripples_dome_photo", "Strong ripples on a dome, photo passes", lambda r: ripples.table(r["records"])),
        ("dome_alone", "The pillow dome alone", lambda r: ripples.table(r["records"])),
        ("displacement_truth", "Displacement against a known truth", lambda r: truth.table(r["records"])),
        ("growth_mirror", "Region growth: the mirror test", lambda r: mirror.table(r["rows"])),
        ("waves_peers", "The waves photo against independent peers", peers.table),
        ("waves_replica", "Replicas of the waves photo with a known displacement", peers.replica_table),
        ("waves_peers_farneback", "The Farneback peer over its settings", peers.sweep_table),
    ]
    parts = []
    for name, title, fn in sections:
        rec = _record(f"{name}.json")
        notes = _notes(f"{name}.md")
        body = f"({name})=\n## {title}\n\n{fn(rec)}\n\n{_source(name + '.json')}"
        parts.append(body + (f"\n\n{_demote(notes, 2)}" if notes else ""))
    return "\n\n".join(parts) + "\n"


def uncertainty_page() -> str:
    rec = _record("uncertainty_calibration.json")
    cols = ("pattern", "period_px", "noise_std", "sigma_periods", "method", "realisations", "trusted_pixels")
    chans = [k for k in ("phi_eff", "phi_shear", "disp_x") if k in rec["records"][0]]
    stats = [k for k, v in rec["records"][0][chans[0]].items() if isinstance(v, (int, float))]
    head = list(cols) + [f"{c} {s}" for c in chans for s in stats]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rec["records"]:
        cells = [_fmt(r.get(c)) for c in cols] + [_fmt(r[c].get(s)) for c in chans for s in stats]
        lines.append("| " + " | ".join(cells) + " |")
    parts = ["## Per-pixel uncertainty against repeated noisy renders", "\n".join(lines),
             _source("uncertainty_calibration.json")]
    for name in ("uncertainty_strong.json", "uncertainty_strong_n2.json"):
        r = _record(name)
        parts += [f"## `{name}`", _nested_table(r["records"]), _source(name)]
    return "\n\n".join(parts) + "\n"


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, (list, tuple)):
        return " × ".join(_fmt(x) for x in v)
    return "" if v is None else _cell(v)


def _nested_table(d: dict) -> str:
    """``{row: {column: value or {sub: value}}}`` as one table (nested keys joined by a dot)."""
    def flat(x, prefix=""):
        for k, v in x.items():
            if isinstance(v, dict):
                yield from flat(v, f"{prefix}{k}.")
            else:
                yield f"{prefix}{k}", v

    rows = {name: dict(flat(v)) for name, v in d.items()}
    cols = list(dict.fromkeys(c for r in rows.values() for c in r))
    lines = ["| | " + " | ".join(_cell(c) for c in cols) + " |", "|---|" + "---|" * len(cols)]
    for name, r in rows.items():
        lines.append(f"| {name} | " + " | ".join(_fmt(r.get(c)) for c in cols) + " |")
    return "\n".join(lines)


def performance_page() -> str:
    cli = _bench("bench_cli")
    parts = []
    rec = _record("performance/cli_processes.json")
    parts += ["## What a user waits for: whole commands against one load + rfft2 process",
              (f"{rec['cpus']} cores, load average {rec['load_average_before'][0]:g} before the run and "
               f"{rec['load_average_after'][0]:g} after it (1-minute). Medians (wall; CPU: user + system of the "
               f"process and its children) of {len(rec['rows'][0]['walls_s'])} "
               "alternating rounds; the unit: one process that starts Python, loads the image and runs one "
               "`numpy.fft.rfft2` of it. `(baseline)`: the same command from the checkout the note names. "
               "The record's note: " + _cell(rec["note"])),
              cli.process_table(rec["rows"]), _source("performance/cli_processes.json")]
    rec = _record("performance/results.json")
    parts += ["## The analysis in Python (`bench_analyze.py`)", rec["table"].strip(), _source("performance/results.json")]
    rec = _record("performance/cli_results.json")
    parts += ["## The command line (`bench_cli.py`)", cli.table(rec["rows"]), _source("performance/cli_results.json")]
    rec = _record("performance/cli_floor.json")
    parts += ["## The command's floor: import and reading", cli.table(rec["rows"]), _source("performance/cli_floor.json")]
    rec = _record("performance/cli_24mpx.json")
    rows = [{**r, "image": f"{label}: {r['image']}"} for label, runs in rec["runs"].items() for r in runs]
    parts += ["## Re-runs of the command at 24 Mpx", (f"{rec['cpus']} cores; one row per run and step, each run's time "
              "in units of the rfft2 measured at its start. The record's note: " + _cell(rec["note"])), cli.table(rows), _source("performance/cli_24mpx.json")]
    rec = _record("performance/distributed_results.json")
    parts += ["## Dask: serial against two workers", _nested_table(rec["runs"]),
              (f"{rec['workers']} workers on {rec['cpu_count']} cores. "
               "*Generated from* `docs/records/performance/distributed_results.json`.")]
    rec = _record("performance/history_results.json")
    timed = {k: v for k, v in rec.items() if isinstance(v, dict)}
    parts += ["## The results history", _nested_table(timed),
              (f"{rec['runs']} runs in {rec['lots']} lots, database {rec['database_MB']} MB, filled in {rec['fill_s']} s. "
               "*Generated from* `docs/records/performance/history_results.json`.")]
    return "\n\n".join(parts) + "\n"


def mutation_page() -> str:
    lines = ["| record | module | mutants | killed | survived | other | killed share |", "|---|---|---|---|---|---|---|"]
    survivors = []
    for path in sorted(RECORDS.glob("mutation_*.json")):
        rec = json.loads(path.read_text())
        for module, mutants in rec["modules"].items():
            killed = sum(m["outcome"].startswith("killed") for m in mutants)
            survived = sum(m["outcome"] == "survived" for m in mutants)
            other = len(mutants) - killed - survived
            share = f"{100 * killed / len(mutants):.0f} %" if mutants else "—"
            lines.append(f"| `{path.name}` | {module} | {len(mutants)} | {killed} | {survived} | {other} | {share} |")
            survivors += [(path.name, module, m) for m in mutants if m["outcome"] == "survived"]
    parts = ["\n".join(lines), ("*Generated from* `docs/records/mutation_*.json`, written by `scripts/mutation.py`. "
                                 "*Killed* counts a mutant whose tests timed out; *other*: any other outcome a record holds.")]
    if survivors:
        rows = ["| record | module | line | source | mutant |", "|---|---|---|---|---|"]
        for name, module, m in survivors:
            rows.append(f"| `{name}` | {module} | {m['line']} | `{_cell(m['source'])}` | "
                        f"`{_cell(m.get('mutant_context', ''))}` |")
        parts += ["## Surviving mutants", "\n".join(rows)]
    return "\n\n".join(parts) + "\n"


PAGES = {
    "fields.md": fields_page,
    "spec_schema.md": spec_schema_page,
    "scene_schema.md": scene_schema_page,
    "summary_keys.md": summary_keys_page,
    "validation_accuracy.md": accuracy_page,
    "validation_experiments.md": experiments_page,
    "validation_benchmarks.md": benchmarks_page,
    "validation_uncertainty.md": uncertainty_page,
    "validation_performance.md": performance_page,
    "validation_mutation.md": mutation_page,
}


def generate(app=None) -> None:
    """Write every page of :data:`PAGES` (only those whose text changed, so that Sphinx rebuilds only them)."""
    OUT.mkdir(exist_ok=True)
    for name, make in PAGES.items():
        text = make()
        path = OUT / name
        if not path.exists() or path.read_text() != text:
            path.write_text(text)


_BARS = re.compile(r"(?<![\\|`])\|([^|\s`](?:[^|`\n]*[^|\s`])?)\|(?![_|])")


def escape_bars(app, what, name, obj, options, lines) -> None:
    """``|phi|`` in a docstring is an absolute value, not a reStructuredText substitution."""
    for i, line in enumerate(lines):
        s = line.strip()
        table_row = s.startswith(("+-", "+=")) or (s.startswith("|") and s.endswith("|") and s.count(" | ") > 0)
        if "|" in line and not table_row:
            lines[i] = _BARS.sub(lambda m: "\\|" + m.group(1) + "\\|", line)


def _lookup(name: str):
    """``(object, module holding it)`` for a dotted name of the package, or None when it does not exist."""
    parts = name.split(".")
    for i in range(len(parts), 0, -1):
        modname = ".".join(parts[:i])
        if modname != "glassdist" and not modname.startswith("glassdist."):
            return None
        try:
            obj = importlib.import_module(modname)
        except ImportError:
            continue
        holder = modname
        rest = parts[i:]
        for k, attr in enumerate(rest):
            if isinstance(obj, types.ModuleType):
                holder = obj.__name__
            if hasattr(obj, attr):
                obj = getattr(obj, attr)
            elif k == len(rest) - 1 and attr in (getattr(obj, "__dataclass_fields__", None)
                                                 or getattr(obj, "model_fields", None) or {}):
                return obj, holder  # a field of a dataclass or a model: its class is its entry
            else:
                return None
        return obj, holder
    return None


def resolve_code_reference(app, env, node, contnode):
    """A Python reference to a name of the package that Sphinx did not find by its written name.

    Docstrings name objects where they are used (``InputError`` in a module that imports it,
    ``glassdist.analyzer.AnalysisResult`` re-exported from its module, a private helper): the
    name is looked up in the code, from the referring module outwards. It resolves to the
    object's documented canonical entry, else to the documented module that holds it. A name
    that the code does not have (a renamed or removed function) stays unresolved and fails
    the strict build.
    """
    from sphinx.util.nodes import make_refnode

    if node.get("refdomain") != "py":
        return None
    target = node["reftarget"].lstrip(".~")
    module, cls = node.get("py:module"), node.get("py:class")
    # the module the docstring was written in (the page may document it under another name)
    source = str(node.source or "")
    written_in = source.rpartition("docstring of ")[2] or None
    scopes = []
    for where in filter(None, (f"{module}.{cls}" if module and cls else None, written_in, module)):
        parts = where.split(".")
        scopes += [".".join(parts[:i]) for i in range(len(parts), 0, -1) if ".".join(parts[:i]) not in scopes]
    candidates = [target] + [f"{s}.{target}" for s in scopes]
    py = env.get_domain("py")
    for cand in candidates:
        found = _lookup(cand)
        if found is None:
            continue
        obj, holder = found
        names = [cand]
        defined = isinstance(obj, type) or callable(obj) and hasattr(obj, "__qualname__")
        if defined and getattr(obj, "__module__", None):
            names.insert(0, f"{obj.__module__}.{obj.__qualname__}")
        if isinstance(obj, types.ModuleType):
            names.insert(0, obj.__name__)
        for name in names:
            if name in py.objects:
                entry = py.objects[name]
                return make_refnode(app.builder, node["refdoc"], entry.docname, entry.node_id, contnode, name)
        home = (obj.__module__ if defined and isinstance(getattr(obj, "__module__", None), str) else None) or holder
        while home:
            if home in py.modules:
                entry = py.modules[home]
                return make_refnode(app.builder, node["refdoc"], entry.docname, entry.node_id, contnode, home)
            home = home.rpartition(".")[0]
    # a name the referring module does not import (a type named in prose): the one documented
    # object of the package whose name ends with it, or with its parent (an undocumented method)
    for name in (target, target.rpartition(".")[0]):
        if not name:
            continue
        hits = [k for k in py.objects if k.startswith("glassdist.") and k.endswith("." + name)]
        if len(hits) == 1:
            entry = py.objects[hits[0]]
            return make_refnode(app.builder, node["refdoc"], entry.docname, entry.node_id, contnode, hits[0])
    return None


class DocstringSectionsAreNotLabels:
    """Section titles of a module docstring (``References``, ``Conventions``) stay local to its page.

    Parsed inside ``automodule`` they are registered as explicit targets, hence as site-wide
    labels, and every module with a ``References`` section would clash with the others.
    """

    @staticmethod
    def make():
        from docutils import nodes
        from docutils.transforms import Transform

        class _Transform(Transform):
            default_priority = 840  # before Sphinx registers the labels (SphinxDomains, 850)

            def apply(self):
                doc = self.document
                for name, explicit in list(doc.nametypes.items()):
                    node = doc.ids.get(doc.nameids.get(name) or "")
                    if explicit and isinstance(node, nodes.section) and "docstring of" in str(node.source or ""):
                        doc.nametypes[name] = False

        return _Transform


def skip_library_members(app, what, name, obj, skip, options):
    """Members a class inherits from SQLAlchemy or pydantic (``metadata``, ``registry``) are theirs."""
    owner = getattr(type(obj), "__module__", "") or ""
    if what == "class" and owner.startswith(("sqlalchemy", "pydantic")):
        return True
    return None


def setup(app: types.SimpleNamespace):
    app.connect("autodoc-skip-member", skip_library_members)
    app.add_transform(DocstringSectionsAreNotLabels.make())
    app.connect("missing-reference", resolve_code_reference)
    app.connect("builder-inited", generate)
    app.connect("autodoc-process-docstring", escape_bars)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
