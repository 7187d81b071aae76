"""Architecture rules that the layout of valve_gym promises (README, "Architecture")."""
from __future__ import annotations

import ast
import pathlib

ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGES = ("valve_gym",)
MAX_LINES = 80  # body lines of a function, docstring excluded


def _modules():
    mods = {}
    for pkg in PACKAGES:
        for p in (ROOT / pkg).rglob("*.py"):
            parts = p.relative_to(ROOT).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            mods[name] = p
    return mods


def _imports(name: str, path: pathlib.Path, mods: dict) -> set:
    """Modules of the project imported at module level (imports inside functions are lazy by design)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    out = set()
    for node in tree.body:
        nodes = [node] if isinstance(node, (ast.Import, ast.ImportFrom)) else []
        if isinstance(node, (ast.If, ast.Try)):
            nodes = [n for n in ast.walk(node) if isinstance(n, (ast.Import, ast.ImportFrom))]
        for n in nodes:
            if isinstance(n, ast.ImportFrom):
                base = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
                if n.level:
                    base = base[:len(base) - (n.level - 1)]
                    target = ".".join(base + ([n.module] if n.module else []))
                else:
                    target = n.module or ""
                cands = [target] + [f"{target}.{a.name}" for a in n.names]
            else:
                cands = [a.name for a in n.names]
            out.update(c for c in cands if c in mods and c != name)
    return out


def _cycles(graph: dict) -> list:
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on, comps, counter = {}, {}, [], set(), [], [0]

    def parents(m):
        parts = m.split(".")
        return {".".join(parts[:i]) for i in range(1, len(parts))}

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w in parents(v):  # a package is always imported before its modules
                continue
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
                comps.append(sorted(comp))

    for v in graph:
        if v not in index:
            visit(v)
    return comps


def test_no_import_cycles():
    mods = _modules()
    graph = {m: _imports(m, p, mods) for m, p in mods.items()}
    assert graph["valve_gym.agents.bench.pipeline"], "the import graph must see the benchmark's imports"
    assert _cycles(graph) == []


def test_cycle_finder_finds_a_cycle():
    assert _cycles({"a.x": {"a.y"}, "a.y": {"a.x"}, "a.z": set()}) == [["a.x", "a.y"]]


def _is_numba(fn: ast.FunctionDef) -> bool:
    for d in fn.decorator_list:
        src = ast.unparse(d)
        if "njit" in src or "jit" in src:
            return True
    return False


def test_functions_are_short():
    long = []
    for p in _modules().values():
        for node in ast.walk(ast.parse(p.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and not _is_numba(node):
                doc = ast.get_docstring(node)
                n = node.end_lineno - node.lineno + 1 - (len(doc.splitlines()) + 2 if doc else 0)
                if n > MAX_LINES:
                    long.append(f"{p.relative_to(ROOT)}:{node.lineno} {node.name} ({n} lines)")
    assert long == []


def test_one_name_per_quantity_in_each_layer():
    from valve_gym.quantities import QUANTITIES, name_of
    for layer in ("physics", "control"):
        names = [getattr(q, layer) for q in QUANTITIES]
        assert len(names) == len(set(names)), f"a {layer} name is used for two quantities"
    # a name used by both layers means the same quantity in both
    both = {q.physics for q in QUANTITIES} & {q.control for q in QUANTITIES}
    for n in both:
        assert [q for q in QUANTITIES if q.physics == n] == [q for q in QUANTITIES if q.control == n]
    assert "(physics: u, control: op)" in name_of("u")
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert "valve_gym/quantities.py" in readme


def test_benchmark_scripts_compile():
    """Every script in benchmarks/ compiles (ruff does not see every compile-time error, e.g. a late ``global``)."""
    scripts = sorted((ROOT / "benchmarks").glob("*.py"))
    assert scripts
    for p in scripts:
        compile(p.read_text(encoding="utf-8"), str(p), "exec")
