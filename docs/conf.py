"""Sphinx configuration of the delayed-rl documentation site (built from the docstrings).

Build it with ``sphinx-build -W --keep-going -b html docs docs/_build/html`` (the ``docs``
extra). Before Sphinx reads the sources, :func:`generate` writes the pages made from the
repository itself into ``docs/_generated/``: one page per experiment (its module docstring and
the committed report with its figures, from ``benchmarks/reproduction/NAME/``), the grid
world's rendered frames and the table of the agent registry.
"""

from __future__ import annotations

import json
import re
import shutil
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path.insert(0, str(ROOT))

project = "delayed-rl"
author = "the delayed-rl developers"
copyright = "2026, the delayed-rl developers"  # noqa: A001 (Sphinx's name)

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.viewcode",
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build", "README.md"]
myst_enable_extensions = ["dollarmath", "colon_fence"]
myst_heading_anchors = 3
html_theme = "furo"
html_title = "delayed-rl"

autodoc_default_options = {"members": True, "show-inheritance": True}
autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_typehints_description_target = "documented"
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_use_rtype = False

# Every internal cross-reference must resolve (a broken one is a warning, and -W makes it an
# error); references into other projects are not checked (the build has no internet for
# intersphinx), so their names are let through here.
nitpicky = True
nitpick_ignore_regex = [
    (
        r"py:.*",
        r"(np|numpy|gym|gymnasium|torch|stable_baselines3|pymunk|numba|joblib|ray|dask"
        r"|pettingzoo|supersuit)(\..*)?",
    ),
    (
        r"py:.*",
        r"(NDArray|ArrayLike|SupportsFloat|Callable|Sequence|Mapping|Iterable|Any|Path)(\[.*)?",
    ),
    (r"py:.*", r"(collections|collections\.abc|typing|pathlib|argparse|numbers|enum)\..*"),
    (r"py:class", r"(optional|callable|type|int|float|str|bool|dict|list|tuple|None)"),
    (r"py:class", r"abc\.ABC"),
    (r"py:class", r"(spaces\..*|VectorEnv|VecEnv|ParallelEnv|Schedule|Wrapper)"),
]

#: The API reference's sections: (title, package), each with every module below it.
API_SECTIONS = [
    ("Agents", "delayed_rl.agents"),
    ("Deep RL reward models", "delayed_rl.deep"),
    ("Wrappers", "delayed_rl.wrappers"),
    ("Multi-agent wrappers (PettingZoo)", "delayed_rl.multiagent"),
    ("Delay distributions", "delayed_rl.delays"),
    ("Environments", "delayed_rl.envs"),
    ("The compiled path", "delayed_rl.compiled"),
    ("Parallel runs", "delayed_rl.parallel"),
    ("Figures", "delayed_rl.figures"),
    ("Experiments", "delayed_rl.experiments"),
    ("Sweeps", "delayed_rl.sweep"),
    ("The command line", "delayed_rl.cli"),
    ("Internals", "delayed_rl._delay_line"),
    ("Internals: validation", "delayed_rl._validation"),
    ("Internals: numba", "delayed_rl._numba"),
]


def generate() -> None:
    """Write the generated pages into ``docs/_generated/`` (replaced at every build)."""
    out = DOCS / "_generated"
    shutil.rmtree(out, ignore_errors=True)
    (out / "experiments").mkdir(parents=True)
    (out / "api").mkdir()
    _experiment_pages(out / "experiments")
    _report_page(out)
    _deep_rl_results(out)
    _api_pages(out / "api")
    _grid_frames(out)
    _agent_registry(out)


def _agent_registry(out: Path) -> None:
    """The agents' table (:func:`delayed_rl.agents.registry.registry_table`), for the agents page."""
    from delayed_rl.agents.registry import registry_table

    (out / "agent_registry.md").write_text(registry_table(), encoding="utf-8")


def _modules(package: str) -> list[str]:
    """``package`` and every module below it, by dotted name (private ones included)."""
    import importlib
    import pkgutil

    root = importlib.import_module(package)
    if not hasattr(root, "__path__"):
        return [package]
    found = pkgutil.walk_packages(root.__path__, prefix=package + ".")
    return [package, *sorted(info.name for info in found)]


def _api_pages(out: Path) -> None:
    """One page per section of :data:`API_SECTIONS`: every module, each documented once.

    Objects are documented where they are defined; a reference to a re-exported name
    (``delayed_rl.wrappers.RewardDelay``) finds its definition (:func:`_resolve_by_identity`).
    """
    pages = []
    for title, package in API_SECTIONS:
        name = package.strip("_").replace(".", "-")
        blocks = [
            f".. automodule:: {module}\n   :ignore-module-all:" for module in _modules(package)
        ]
        body = "\n\n".join(blocks)
        (out / f"{name}.md").write_text(f"# {title}\n\n```{{eval-rst}}\n{body}\n```\n")
        pages.append(name)
    listing = "\n".join(pages)
    (out / "index.md").write_text(
        "# API reference\n\nEvery module, every public name, from the docstrings.\n\n"
        f"```{{toctree}}\n:maxdepth: 1\n\n{listing}\n```\n"
    )


def _experiment_pages(out: Path) -> None:
    """One page per experiment: its module's docstring, then its committed report and figures."""
    from delayed_rl.experiments import _MODULES

    entries = []
    for name, module in _MODULES.items():
        results = ROOT / "benchmarks" / "reproduction" / name
        if (results / "report.md").exists():
            ignored = shutil.ignore_patterns("*.csv*", "*.json", "runs")
            shutil.copytree(results, out / name, ignore=ignored)
            shown = (
                f"The committed run (`benchmarks/reproduction/{name}/`):\n\n"
                f"```{{include}} {name}/report.md\n:relative-images:\n:heading-offset: 2\n```\n"
            )
        else:  # a long experiment whose run is still in parts (its kept runs only)
            shown = f"No committed report yet: `benchmarks/reproduction/{name}/` has none.\n"
        (out / f"{name}.md").write_text(
            f"# {name}\n\n"
            f"`delayed-rl bench {name}` — {{mod}}`delayed_rl.experiments.{module}`.\n\n"
            f"```{{eval-rst}}\n.. automodule:: delayed_rl.experiments.{module}\n"
            f"   :no-members:\n   :no-index:\n```\n\n"
            f"## Results\n\n{shown}"
        )
        entries.append(name)
    toctree = "\n".join(entries)
    (out / "index.md").write_text(
        "# The experiments\n\n"
        "Every thesis experiment (and those beyond it), as `delayed-rl bench NAME` runs it: what "
        "it measures, then the committed run's report — each claim beside the thesis's value, "
        "its 95 % interval over seeds, its verdict and the criterion that decides it — and "
        "figures. {doc}`/_generated/reproduction` explains the differences.\n\n"
        f"```{{toctree}}\n:maxdepth: 1\n\n{toctree}\n```\n"
    )


def _deep_rl_results(out: Path, results: Path | None = None) -> None:
    """``deep_rl_results.md``: the committed ``deep-rl`` run as a table, with its target verdicts.

    Per setting and method: the mean score (10 greedy episodes of the undelayed env), the gain
    (0 random, 1 the oracle), the reward model's RMSE and the learned mean delay, each mean ±
    95 % CI over seeds.
    """
    results = results or ROOT / "benchmarks" / "reproduction" / "deep-rl" / "summary.json"
    if not results.exists():
        (out / "deep_rl_results.md").write_text("No committed run of `deep-rl` yet.\n")
        return
    summary = json.loads(results.read_text())

    def cell(row: dict, key: str, digits: int) -> str:
        if key not in row:
            return ""
        return f"{row[key]['mean']:.{digits}f} ± {row[key]['ci95']:.{digits}f}"

    lines = [
        f"Each setting's seeds count from {summary['config']['base_seed']}.\n",
        "| setting | method | seeds | score | gain | RMSE of R̂ | mean delay |",
        "|---|---|---|---|---|---|---|",
    ]
    for setting, rows in summary["table"].items():
        for method, row in rows.items():
            lines.append(
                f"| {setting} | {method} | {len(row['seeds'])} | {cell(row, 'score', 1)} | "
                f"{cell(row, 'gain', 2)} | {cell(row, 'rmse', 2)} | {cell(row, 'mean_delay', 1)} |"
            )
    lines += ["", "| target | measured | verdict |", "|---|---|---|"]
    for claim in summary["claims"]:
        if claim["thesis"].startswith("target"):
            measured = f"{claim['mean']:.2f} [{claim['low']:.2f}, {claim['high']:.2f}]"
            lines.append(f"| {claim['quantity']} ({claim['thesis']}) | {measured} | "
                         f"{claim['verdict']} |")  # fmt: skip
    (out / "deep_rl_results.md").write_text("\n".join(lines) + "\n")


def _report_page(out: Path) -> None:
    """``benchmarks/REPORT.md`` as a page: its links to reports lead to the experiment pages."""
    text = (ROOT / "benchmarks" / "REPORT.md").read_text()
    text = re.sub(r"\]\(reproduction/([\w-]+)/report\.md\)", r"](experiments/\1.md)", text)
    text = text.replace("](reproduction/", "](../../benchmarks/reproduction/")
    (out / "reproduction.md").write_text(text)


def _grid_frames(out: Path) -> None:
    """The text frames ``GridWorldEnv.render()`` draws (``render_mode="ansi"``)."""
    import gymnasium as gym

    import delayed_rl  # noqa: F401  (registers the ids)

    frames = []
    for size in (3, 5, 9):
        env = gym.make(f"delayed_rl/GridWorld-{size}x{size}-v0", render_mode="ansi")
        env.reset(seed=0)
        frames.append(f"{size}×{size}, at the start:\n\n```text\n{env.render()}```\n")
    (out / "gridworld_frames.md").write_text("\n".join(frames))


def _object(dotted: str):
    """The Python object named ``dotted`` (a module, or an attribute path in one), or None."""
    import importlib

    parts = dotted.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            value = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        try:
            for part in parts[cut:]:
                value = getattr(value, part)
        except AttributeError:
            return None
        return value
    return None


_DOCUMENTED: dict[int, str] = {}


def _resolve_by_identity(app, env, node, contnode):
    """Resolve a Python reference Sphinx did not: by the object it names, or by a unique suffix.

    ``:class:`~delayed_rl.wrappers.RewardDelay``` names the class where the package re-exports
    it; the reference docs hold it where it is defined,
    ``delayed_rl.wrappers.reward_delay.RewardDelay``: the object is imported and its documented
    name found. A bare name (``RewardDelay`` in a module that does not import it) resolves when
    exactly one documented object ends with it. A private name (``_credit_many``) is not in the
    reference docs: it stays as code. Anything else is left to Sphinx's warning.
    """
    if node.get("refdomain") != "py":
        return None
    domain = env.get_domain("py")
    if not _DOCUMENTED:
        for name in domain.objects:
            value = _object(name)
            if value is not None and not isinstance(value, (int, float, str, bytes, tuple)):
                _DOCUMENTED.setdefault(id(value), name)
    target = node["reftarget"].lstrip(".~")
    module, cls = node.get("py:module"), node.get("py:class")
    candidates = [target]
    if module:
        candidates += [f"{module}.{cls}.{target}" if cls else "", f"{module}.{target}"]
    found = None
    for candidate in filter(None, candidates):
        value = _object(candidate)
        found = _DOCUMENTED.get(id(value)) if value is not None else None
        if found is not None:
            break
    if found is None:
        suffix = [name for name in domain.objects if name.endswith("." + target)]
        found = suffix[0] if len(suffix) == 1 else None
    if found is None:
        return contnode if target.rsplit(".", 1)[-1].startswith("_") else None
    from sphinx.util.nodes import make_refnode

    entry = domain.objects[found]
    return make_refnode(app.builder, node["refdoc"], entry.docname, entry.node_id, contnode, found)


_PIPES = re.compile(r"(?<![\\|`])\|([^|\s`][^|`]*?)\|(?![|`])")


def _escape_pipes(app, what, name, obj, options, lines):
    """Escape ``|S|``-style magnitudes (outside inline literals): not RST substitutions."""
    for i, line in enumerate(lines):
        row = line.strip()
        if "|" not in line or row.startswith("+") or (row.startswith("|") and row.endswith("|")):
            continue  # a table row is left alone
        parts = line.split("``")
        parts[::2] = [_PIPES.sub(r"\\|\1\\|", part) for part in parts[::2]]
        lines[i] = "``".join(parts)


_SEPARATOR = re.compile(r"^\|(\s*:?-+:?\s*\|)+$")


def _markdown_to_rst(app, what, name, obj, options, lines):
    """Turn the Markdown of Minigrid-style env docstrings into RST, before napoleon reads them.

    ``## Title`` lines become rubrics, and Markdown tables (a header row, a ``|---|`` row, body
    rows) become list tables.
    """
    out: list[str] = []
    i = 0
    while i < len(lines):
        line = lines[i]
        text, indent = line.strip(), line[: len(line) - len(line.lstrip())]
        if text.startswith("## "):
            out += [f"{indent}.. rubric:: {text[3:]}", ""]
            i += 1
            continue
        if text.startswith("|") and i + 1 < len(lines) and _SEPARATOR.match(lines[i + 1].strip()):
            rows = [text]
            i += 2
            while i < len(lines) and lines[i].strip().startswith("|"):
                rows.append(lines[i].strip())
                i += 1
            out += _list_table(rows, indent)
            continue
        out.append(line)
        i += 1
    lines[:] = out


def _list_table(rows: list[str], indent: str) -> list[str]:
    """A Markdown table's rows (header first) as an RST ``list-table``."""
    table = [f"{indent}.. list-table::", f"{indent}   :header-rows: 1", ""]
    for row in rows:
        cells = [cell.strip() for cell in row.strip("|").split("|")]
        table.append(f"{indent}   * - {cells[0]}")
        table += [f"{indent}     - {cell}" for cell in cells[1:]]
    return [*table, ""]


def _skip_tuple_fields(app, what, name, obj, skip, options):
    """Skip a NamedTuple's field accessors: its "Attributes:" section documents them."""
    if type(obj).__name__ == "_tuplegetter":
        return True
    return None


_HELD: dict[str, list[str]] = {}


def _hold_attribute_docstring(app, what, name, obj, options, lines):
    """Keep an attribute's or property's docstring from napoleon, put back after it.

    Napoleon would read the first line's "X: Y" as "type: description";
    :func:`_restore_attribute_docstring` puts the docstring back as written.
    """
    if what in ("attribute", "data", "property") and lines:
        _HELD[name] = list(lines)
        lines[:] = []


def _restore_attribute_docstring(app, what, name, obj, options, lines):
    """Put back what :func:`_hold_attribute_docstring` held."""
    if name in _HELD:
        lines[:] = _HELD.pop(name)


def setup(app):
    """Register the hooks: references by identity, attribute docstrings kept as written."""
    app.connect("missing-reference", _resolve_by_identity)
    app.connect("autodoc-process-docstring", _markdown_to_rst, priority=50)
    app.connect("autodoc-process-docstring", _hold_attribute_docstring, priority=100)
    app.connect("autodoc-process-docstring", _restore_attribute_docstring, priority=900)
    app.connect("autodoc-process-docstring", _escape_pipes, priority=950)
    app.connect("autodoc-skip-member", _skip_tuple_fields)


generate()
