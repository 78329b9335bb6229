"""The import graph of solver/ and sweep/ has no circle, solver/ never imports sweep/ (issue #50), and every module
imports only its own floor and those below (README.md, "Layout").

Read statically with ``ast``: every ``import`` and ``from ... import`` of a module counts, at module level or inside a
function (a function-level import is still an arrow of the architecture).  The check is shown to fail on a
deliberately circular toy package.
"""
from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("solver", "sweep")


def module_files(root: Path, packages) -> dict[str, Path]:
    """{dotted module name: file} of every module of ``packages`` under ``root`` (a package is its __init__)."""
    out = {}
    for pkg in packages:
        for f in sorted((root / pkg).rglob("*.py")):
            parts = f.relative_to(root).with_suffix("").parts
            out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = f
    return out


def _targets(node, module: str, is_package: bool, known) -> set[str]:
    """The modules of ``known`` that one import statement of ``module`` names."""
    if isinstance(node, ast.Import):
        names = [a.name for a in node.names]
    else:
        base = node.module or ""
        if node.level:
            here = module.split(".") if is_package else module.split(".")[:-1]
            here = here[: len(here) - (node.level - 1)]
            base = ".".join([*here, base] if base else here)
        names = [f"{base}.{a.name}" if f"{base}.{a.name}" in known else base for a in node.names]
    out = set()
    for n in names:
        while n and n not in known:     # `import a.b.c` of a name inside a module: the module
            n = n.rpartition(".")[0]
        if n:
            out.add(n)
    return out


def import_graph(root: Path, packages=PACKAGES) -> dict[str, set[str]]:
    """{module: modules of ``packages`` it imports anywhere in its text}."""
    files = module_files(root, packages)
    graph = {}
    for mod, f in files.items():
        tree = ast.parse(f.read_text(encoding="utf-8"), filename=str(f))
        deps = set()
        for node in ast.walk(tree):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                deps |= _targets(node, mod, f.name == "__init__.py", files)
        graph[mod] = deps - {mod}
    return graph


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
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


def test_no_import_circle_in_solver_or_sweep():
    graph = import_graph(ROOT)
    assert len(graph) > 50, sorted(graph)            # the packages were found
    assert circles(graph) == []


def test_solver_never_imports_sweep():
    graph = import_graph(ROOT)
    up = {m: sorted(d for d in deps if d.split(".")[0] == "sweep") for m, deps in graph.items() if m.startswith("solver")}
    assert {m: d for m, d in up.items() if d} == {}


def test_the_check_finds_a_circle_in_a_toy_package(tmp_path):
    pkg = tmp_path / "toy"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "low.py").write_text("import math\n\n\ndef f():\n    from toy.sub.high import g\n    return g\n")
    (pkg / "sub" / "high.py").write_text("from ..low import f\n\n\ndef g():\n    return f\n")
    (pkg / "apart.py").write_text("from toy import low\n")
    graph = import_graph(tmp_path, ("toy",))
    assert graph["toy.apart"] == {"toy.low"}
    assert circles(graph) == [["toy.low", "toy.sub.high"]]
    (pkg / "low.py").write_text("import math\n")            # the upward import removed: no circle
    assert circles(import_graph(tmp_path, ("toy",))) == []


#: the floors of README.md "Layout", lowest first: a module imports only its own floor and those below.  figio (the
#: figure writer) and paper (the paper's reported values) are leaves every floor may use; studies/ and discrepancy/
#: share a floor (the discrepancy workflow's reference check reuses studies/reference).
FLOORS = (("solver",), ("sweep.figio", "sweep.paper"), ("sweep.regimes",), ("sweep.campaign",),
          ("sweep.studies", "sweep.discrepancy"), ("sweep.cli", "sweep.animate", "sweep"))


def floor(module: str) -> int:
    """The floor of a module: the longest prefix of FLOORS that names it or its package."""
    best = (-1, -1)
    for i, prefixes in enumerate(FLOORS):
        for p in prefixes:
            if module == p or module.startswith(p + "."):
                best = max(best, (len(p), i))
    return best[1]


def upward(graph: dict[str, set[str]]) -> dict[str, list[str]]:
    """{module: the modules it imports from a higher floor}, for the modules that do."""
    up = {m: sorted(d for d in deps if floor(d) > floor(m)) for m, deps in graph.items()}
    return {m: d for m, d in up.items() if d}


def test_every_module_imports_only_its_floor_and_those_below():
    graph = import_graph(ROOT)
    assert all(floor(m) >= 0 for m in graph), [m for m in graph if floor(m) < 0]
    assert upward(graph) == {}
    toy = {"sweep.regimes.a": {"sweep.campaign.b", "sweep.figio"}, "sweep.campaign.b": {"sweep.regimes.a"}}
    assert upward(toy) == {"sweep.regimes.a": ["sweep.campaign.b"]}  # the check sees an arrow up
