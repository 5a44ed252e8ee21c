"""Import rules of the code base, checked on the source (AST), every import counted (also inside functions).

* ``ptw_env`` (the simulator) never imports ``assist``;
* no library module imports the command line (``ptw_env.cli``, ``assist.cli``, ``assist.cli.control``,
  ``assist.*_cli``); only command-line modules do;
* the families of ``assist`` import one another only along the stated arrows (:data:`ARROWS`);
* no name starting with an underscore is imported across top-level packages;
* no import circle among the modules (imports under ``if TYPE_CHECKING:`` are not run and do not count;
  ``from pkg import module`` depends on the module, not on ``pkg/__init__``).

Each rule is also run on a small source that breaks it, so that a checker that finds nothing fails.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("ptw_env", "assist")

#: Modules kept at their pre-1.0 paths for one release (each re-exports its new module with a DeprecationWarning).
COMPAT = ("assist.ts_model", "assist.ts_design", "assist.ts_controller", "assist.lqg", "assist.lpv_model",
          "assist.adaptive_design", "assist.adaptive_observer", "assist.identifiability", "assist.identification",
          "assist.structure", "assist.observability", "assist.differentiator", "assist.hosm", "assist.commands",
          "assist.diagnose_cli", "assist.estimate_cli", "assist.risk_cli", "assist.rl_cli")
#: Family of each module of ``assist``: its folder (``assist.risk.x`` -> risk), the evaluation harness, the
#: command line, and the old paths.
FAMILIES = {
    "control": ("assist.control",),
    "estimation": ("assist.estimation",),
    "unknown_input": ("assist.unknown_input",),
    "rl": ("assist.rl", "assist.policies"),
    "risk": ("assist.risk",),
    "diagnose": ("assist.diagnose",),
    "evaluate": ("assist.evaluate",),
    "lmi": ("assist.lmi",),
    "cli": ("assist.cli",),
    "compat": COMPAT,
}
#: Which family may import which (besides itself and ``ptw_env``): the risk warning runs the estimator, the
#: evaluation harness runs any controller (TS, LQG, RL), both designs share the LMI plumbing, the command line sits
#: on top of everything, and an
#: old path re-exports its new module. Nothing imports an old path.
ARROWS = {
    "control": {"lmi"},
    "estimation": {"lmi"},
    "risk": {"estimation"},
    "evaluate": {"control", "rl"},
    "cli": set(FAMILIES) - {"cli", "compat"},
    "compat": set(FAMILIES) - {"compat"},
}
CLI_MODULES = {"ptw_env.cli", *FAMILIES["cli"], "assist.commands", "assist.diagnose_cli", "assist.estimate_cli",
               "assist.risk_cli", "assist.rl_cli"}


def module_name(path: Path, root: Path = ROOT) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def imports(source: str, module: str, is_package: bool = False) -> list[tuple[int, str, str | None]]:
    """Every import of ``source`` as ``(line, target module, imported name or None)``."""
    out: list[tuple[int, str, str | None]] = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name, None) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split(".") if is_package else module.split(".")[:-1]
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            for a in node.names:
                sub = f"{target}.{a.name}"
                out.append((node.lineno, target, a.name))
                out.append((node.lineno, sub, None))  # ``from pkg import module`` imports that module
    return out


def family_of(module: str) -> str | None:
    for fam, prefixes in FAMILIES.items():
        if any(module == p or module.startswith(p + ".") for p in prefixes):
            return fam
    return None


def violations(module: str, source: str, is_package: bool = False) -> list[str]:
    """The import rules ``module`` breaks (one line each, with the line number)."""
    bad: list[str] = []
    top = module.split(".")[0]
    fam = family_of(module)
    for line, target, name in imports(source, module, is_package):
        ttop = target.split(".")[0]
        if top == "ptw_env" and ttop == "assist":
            bad.append(f"{module}:{line}: the simulator imports {target}")
        if module not in CLI_MODULES and fam not in ("cli", "compat") and \
                any(target == c or target.startswith(c + ".") for c in CLI_MODULES):
            bad.append(f"{module}:{line}: library code imports the command line ({target})")
        tfam = family_of(target)
        if fam and tfam and tfam != fam and tfam not in ARROWS.get(fam, set()):
            bad.append(f"{module}:{line}: family {fam} imports family {tfam} ({target})")
        if ttop in PACKAGES and ttop != top:
            private = [p for p in target.split(".") if p.startswith("_") and not p.startswith("__")]
            if name and name.startswith("_") and not name.startswith("__"):
                private.append(name)
            if private:
                bad.append(f"{module}:{line}: imports the private name(s) {private} of {target}")
    return bad


def _sources():
    for pkg in PACKAGES:
        for f in sorted((ROOT / pkg).rglob("*.py")):
            yield module_name(f), f.read_text(encoding="utf-8"), f.name == "__init__.py"


def module_graph(sources: dict[str, tuple[str, bool]]) -> dict[str, set[str]]:
    """``module -> modules it imports`` among ``sources`` (name -> (source, is_package)), see the module docstring."""
    graph: dict[str, set[str]] = {}
    for m, (src, is_pkg) in sources.items():
        tree = ast.parse(src)
        typing_only = {id(n) for node in ast.walk(tree)
                       if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)
                       for sub in node.body for n in ast.walk(sub)}
        deps: set[str] = set()
        for node in ast.walk(tree):
            if id(node) in typing_only or not isinstance(node, (ast.Import, ast.ImportFrom)):
                continue
            if isinstance(node, ast.Import):
                deps.update(a.name for a in node.names)
                continue
            _, target, _ = imports(ast.unparse(node), m, is_pkg)[0]
            for a in node.names:
                deps.add(f"{target}.{a.name}" if f"{target}.{a.name}" in sources else target)
        graph[m] = {d for d in deps if d in sources and d != m}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_no_import_circle():
    graph = module_graph({m: (src, pkg) for m, src, pkg in _sources()})
    assert cycles(graph) == []


def test_the_circle_finder_finds_a_circle_and_ignores_typing_only_imports():
    sources = {
        "assist.a": ("from .b import f\n", False),
        "assist.b": ("def f():\n    from assist.a import g\n", False),  # a function-level import counts
        "assist.c": ("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .d import X\n", False),
        "assist.d": ("from .c import Y\n", False),
        "assist.e": ("from . import f\n", False),  # the module assist.f, not the package
        "assist": ("from .e import h\n", True),
        "assist.f": ("", False),
    }
    assert cycles(module_graph(sources)) == [["assist.a", "assist.b"]]


def test_every_module_belongs_to_a_family():
    loose = [m for m, _, _ in _sources() if m.startswith("assist.") and family_of(m) is None]
    assert loose == [], f"assist modules outside every family (add them to FAMILIES): {loose}"


def test_the_code_base_keeps_the_import_rules():
    found = [v for m, src, pkg in _sources() for v in violations(m, src, pkg)]
    assert found == [], "\n".join(found)


@pytest.mark.parametrize(
    "module, source, expected",
    [
        ("ptw_env.env", "def f():\n    import assist.unknown_input.hosm\n", "the simulator imports"),
        ("ptw_env.logs", "from assist.risk import monitor\n", "the simulator imports"),
        ("assist.unknown_input.hosm", "from ptw_env.cli import number\n", "library code imports the command line"),
        ("assist.risk.monitor", "from ..risk_cli import x\n", "library code imports the command line"),
        ("assist.diagnose.replay", "from assist.estimation.adaptive_observer import AdaptiveObserver\n", "family diagnose"),
        ("assist.control.ts_design", "from ..unknown_input.hosm import design_uihosmo\n",
         "family control imports family unknown_input"),
        ("assist.risk.pipeline", "from ..adaptive_observer import AdaptiveObserver\n", "family risk imports family compat"),
        ("assist.estimation.identification", "from ptw_env.kernels import _deriv\n", "private name"),
        ("assist.risk.evaluation", "from ptw_env._secret import x\n", "private name"),
    ],
)
def test_the_checker_finds_each_kind_of_violation(module, source, expected):
    found = violations(module, source)
    assert any(expected in v for v in found), found


@pytest.mark.parametrize(
    "module, source",
    [
        ("assist.risk.pipeline", "from ..estimation.adaptive_observer import AdaptiveObserver\n"),  # a stated arrow
        ("assist.evaluate", "from .rl import load_policy\n"),
        ("assist.cli.control", "from assist.cli import risk\nimport ptw_env.cli\nfrom ..control import lqg\n"),
        ("assist.unknown_input.hosm", "from ptw_env.vehicle import REFERENCE_SCOOTER\nfrom .differentiator import _x\n"),
    ],
)
def test_the_checker_accepts_what_the_rules_allow(module, source):
    assert violations(module, source) == []


@pytest.mark.parametrize("old", COMPAT)
def test_an_old_path_still_works_and_says_where_the_module_went(old):
    import importlib
    import sys
    import warnings

    sys.modules.pop(old, None)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        mod = importlib.import_module(old)
    new_name = mod._new.__name__
    assert any(issubclass(w.category, DeprecationWarning) and new_name in str(w.message) for w in caught)
    new = importlib.import_module(new_name)
    public = getattr(new, "__all__", [n for n in vars(new) if not n.startswith("_")])
    for name in public:
        assert getattr(mod, name) is getattr(new, name), (old, name)


def test_the_tests_and_scripts_use_the_new_paths():
    """An old path imported by our own code would hide a missing re-export (and monkeypatch the wrong module)."""
    found = []
    for folder in ("tests", "scripts"):
        for f in sorted((ROOT / folder).glob("*.py")):
            for line, target, _ in imports(f.read_text(encoding="utf-8"), f"{folder}.{f.stem}"):
                if target in COMPAT:
                    found.append(f"{folder}/{f.name}:{line}: imports the old path {target}")
    assert found == [], "\n".join(found)
