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


# --------------------------------------------------------------------------- one implementation per concept
def _sources():
    """``(relative path, parsed module)`` of every module of the package."""
    return [(str(p.relative_to(ROOT)), ast.parse(p.read_text(encoding="utf-8"))) for p in _modules().values()]


def _called(node: ast.Call) -> str:
    """Name of the called function (``f`` for ``f(...)`` and ``m.f(...)``)."""
    f = node.func
    return f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else ""


def _name(node) -> str:
    return node.id if isinstance(node, ast.Name) else node.attr if isinstance(node, ast.Attribute) else ""


def _functions(tree):
    return [n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]


def find_detectors(sources) -> set:
    """Oscillation detectors: code that reads the zero crossings of an autocorrelation, a class named
    ``Oscillation`` or a function with a retired detector's name."""
    out = set()
    for path, tree in sources:
        for n in ast.walk(tree):
            if isinstance(n, ast.Call) and _called(n) == "acf_zero_crossings":
                out.add(f"{path}: reads ACF zero crossings")
            if isinstance(n, ast.ClassDef) and n.name in ("Oscillation", "LimitCycle", "AcfOscillation"):
                out.add(f"{path}: class {n.name}")
            if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) and n.name in (
                    "limit_cycle", "acf_oscillation", "oscillation_index", "detect_oscillation"):
                out.add(f"{path}: def {n.name}")
    return out


def find_autocorrelations(sources) -> set:
    """FFT autocorrelations: ``irfft(f * conj(f))`` (the same spectrum on both sides)."""
    out = set()
    for path, tree in sources:
        for n in ast.walk(tree):
            if isinstance(n, ast.Call) and _called(n) == "irfft" and n.args:
                a = n.args[0]
                if isinstance(a, ast.BinOp) and isinstance(a.op, ast.Mult):
                    sides = [a.left, a.right]
                    conj = [s for s in sides if isinstance(s, ast.Call) and _called(s) == "conj" and s.args]
                    if conj and any(ast.dump(s) == ast.dump(conj[0].args[0]) for s in sides):
                        out.add(f"{path}:{n.lineno}")
    return out


def find_first_order_recursions(sources) -> set:
    """Ornstein-Uhlenbeck generators written out: ``x[k] = a * x[k - 1] + ...`` (or ``lfilter(.., [1, -a], ..)``)."""
    out = set()
    for path, tree in sources:
        for n in ast.walk(tree):
            if isinstance(n, ast.Assign) and len(n.targets) == 1 and isinstance(n.targets[0], ast.Subscript) \
                    and isinstance(n.value, ast.BinOp) and isinstance(n.value.op, ast.Add):
                target = _name(n.targets[0].value)
                terms = [n.value.left, n.value.right]
                for t in terms:
                    if isinstance(t, ast.BinOp) and isinstance(t.op, ast.Mult):
                        subs = [s for s in (t.left, t.right)
                                if isinstance(s, ast.Subscript) and _name(s.value) == target]
                        if subs and "- 1" in ast.unparse(subs[0].slice):
                            out.add(f"{path}:{n.lineno}")
            if isinstance(n, ast.Call) and _called(n) == "lfilter" and len(n.args) >= 2 \
                    and isinstance(n.args[1], (ast.List, ast.Tuple)) and len(n.args[1].elts) == 2 \
                    and isinstance(n.args[1].elts[1], ast.UnaryOp):
                out.add(f"{path}:{n.lineno} (lfilter)")
    return out


_PLANT_CALLS = {"run_packed", "advance", "step", "run_packed_reset", "scan"}


def _block_step(c: ast.Call) -> bool:
    """``x.step(sp, pv)``: a DCS block's scan (two positional arguments)."""
    return isinstance(c.func, ast.Attribute) and c.func.attr == "step" and len(c.args) == 2 and not c.keywords


def find_runners(sources) -> set:
    """Closed-loop runners: a ``for`` loop that advances a plant and calls ``pi_step`` or a block's
    ``.step(sp, pv)`` (a second call, beside the plant's own step/advance)."""
    out = set()
    for path, tree in sources:
        for fn in _functions(tree):
            for loop in (n for n in ast.walk(fn) if isinstance(n, ast.For)):
                calls = [c for c in ast.walk(loop) if isinstance(c, ast.Call)]
                names = {_called(c) for c in calls}
                plant = [c for c in calls if _called(c) in _PLANT_CALLS]
                block = [c for c in calls if _block_step(c)]
                if ("pi_step" in names and plant) or any(p is not b for b in block for p in plant):
                    out.add(f"{path}: {fn.name}")
    return out


def find_pi_laws(sources) -> set:
    """PI laws: an integral gain ``Kc ... / Ti`` computed in code."""
    out = set()
    for path, tree in sources:
        for fn in _functions(tree):
            for n in ast.walk(fn):
                if isinstance(n, ast.BinOp) and isinstance(n.op, ast.Div) and _name(n.right) == "Ti" \
                        and "Kc" in ast.unparse(n.left):
                    out.add(f"{path}: {fn.name}")
    return out


def find_model_file_loaders(sources) -> set:
    """Readers of weight files (safetensors ``load_file``/``safe_open``/``load``)."""
    out = set()
    for path, tree in sources:
        for n in ast.walk(tree):
            if isinstance(n, ast.ImportFrom) and (n.module or "").startswith("safetensors") and any(
                    a.name in ("load_file", "safe_open", "load") for a in n.names):
                out.add(path)
    return out


_TABLE_READERS = {"read_csv", "read_parquet", "read_table", "reader", "DictReader", "loadtxt", "genfromtxt"}


def find_recording_readers(sources) -> set:
    """Modules that read tables (CSV, Parquet) themselves: recording loaders."""
    out = set()
    for path, tree in sources:
        if any(isinstance(n, ast.Call) and _called(n) in _TABLE_READERS for n in ast.walk(tree)):
            out.add(path)
    return out


#: The one place of each concept.
DETECTOR = {"valve_gym/oscillation.py: reads ACF zero crossings", "valve_gym/oscillation.py: class Oscillation",
            "valve_gym/oscillation.py: def detect_oscillation"}
AUTOCORRELATION = "valve_gym/signals.py"
OU_GENERATOR = "valve_gym/signals.py"
RUNNER = {"valve_gym/loop.py: run_closed_loop"}
PI_LAW = "valve_gym/control.py"
MODEL_FILE_LOADER = {"valve_gym/agents/safe_files.py"}
RECORDING_LOADER = "valve_gym/diagnosis/recording/"
#: Modules outside the recording pipeline that read tables themselves: none (the fleet's wide exports are read
#: by diagnosis/recording/wide.py).  The set stays empty.
KNOWN_SECOND_LOADER: set[str] = set()
#: Written apart on purpose: the textbook loops that validate the stiction verdict are an independently
#: written simulator (their own PI and plant), so that the validation does not share the product's code.
INDEPENDENT = ("valve_gym/diagnosis/stiction/loops.py",)
#: PI laws outside valve_gym/control.py (the regulation block's scan is control.pi_scan1 since issue 41).
KNOWN_SECOND_PI: set = set()


def _not_independent(found) -> set:
    return {f for f in found if not f.startswith(INDEPENDENT)}


def test_one_oscillation_detector():
    assert find_detectors(_sources()) == DETECTOR


def test_one_autocorrelation_and_one_ou_generator():
    src = _sources()
    assert {f.split(":")[0] for f in find_autocorrelations(src)} == {AUTOCORRELATION}
    assert {f.split(":")[0] for f in _not_independent(find_first_order_recursions(src))} <= {OU_GENERATOR}


def test_one_closed_loop_runner_and_one_pi_law():
    src = _sources()
    assert _not_independent(find_runners(src)) == RUNNER
    laws = _not_independent(find_pi_laws(src))
    assert {f for f in laws if not f.startswith(PI_LAW)} <= KNOWN_SECOND_PI, "a second PI law"


def test_one_model_file_loader_and_one_recording_loader():
    src = _sources()
    assert find_model_file_loaders(src) == MODEL_FILE_LOADER
    readers = find_recording_readers(src)
    assert any(r.startswith(RECORDING_LOADER) for r in readers), "the recording pipeline must be seen"
    assert {r for r in readers if not r.startswith(RECORDING_LOADER)} <= KNOWN_SECOND_LOADER


def test_the_finders_find_second_implementations():
    """Each check fails on a module that writes the concept out again."""
    bad = ast.parse('''
import numpy as np
from scipy.signal import lfilter
from safetensors.numpy import load_file
from valve_gym.signals import acf_zero_crossings

class Oscillation:
    pass

def limit_cycle(x):
    return acf_zero_crossings(x)

def my_acf(x):
    f = np.fft.rfft(x)
    return np.fft.irfft(f * np.conj(f))

def my_ou(w, a):
    x = np.zeros(len(w))
    for k in range(1, len(w)):
        x[k] = a * x[k - 1] + w[k]
    return x, lfilter([1.0], [1.0, -a], w)

def my_loop(plant, pi, ctl, sp):
    for k in range(len(sp)):
        ctl, u = pi_step(ctl, sp[k] - plant.y, pi)
        plant.step(u)

def my_block_loop(plants, ctrl, sp, noise, load):
    lv = sp[0].copy()
    for k in range(len(sp)):
        u = ctrl.step(sp[k], lv + noise[k])
        for idx, p in plants:
            lv[idx] = p.step(u[idx], load[k, idx]).pv

def not_a_loop(bank, sp, pv):
    for b in bank:
        b.step(sp, pv)

def my_pi(Kc, Ti, Ts, e, i):
    return i + Kc * Ts / Ti * e

def my_loader(path):
    import pandas as pd
    return pd.read_csv(path)
''')
    src = [("x/bad.py", bad)]
    assert len(find_detectors(src)) == 3
    assert find_autocorrelations(src) and len(find_first_order_recursions(src)) == 2
    assert find_runners(src) == {"x/bad.py: my_loop", "x/bad.py: my_block_loop"}
    assert find_pi_laws(src) == {"x/bad.py: my_pi"}
    assert find_model_file_loaders(src) == {"x/bad.py"} and find_recording_readers(src) == {"x/bad.py"}


def find_class_name_clashes(sources) -> dict:
    """Class names defined in more than one module: ``{name: [paths]}``."""
    seen: dict = {}
    for path, tree in sources:
        for n in ast.walk(tree):
            if isinstance(n, ast.ClassDef):
                seen.setdefault(n.name, set()).add(path)
    return {k: sorted(v) for k, v in seen.items() if len(v) > 1}


def test_one_class_per_name():
    """One concept, one class: no two modules define a class of the same name (e.g. two RegulationConfigs)."""
    assert find_class_name_clashes(_sources()) == {}
    two = [("a.py", ast.parse("class RegulationConfig:\n    pass\n")),
           ("b.py", ast.parse("class RegulationConfig: ..."))]
    assert find_class_name_clashes(two) == {"RegulationConfig": ["a.py", "b.py"]}


def find_loop_scorers(sources) -> set:
    """Code that scores loops itself: calls of the stem-reversal counter or of the IAE sum outside the scores."""
    out = set()
    for path, tree in sources:
        for n in ast.walk(tree):
            if isinstance(n, ast.Call) and _called(n) in ("reversal_counts", "loop_iae", "valve_motion"):
                out.add(path)
    return out


#: The one loop-scoring module (IAE of the measured error, stem travel and reversals, limit cycles).
LOOP_SCORES = "valve_gym/agents/bench/scores.py"


def test_one_loop_scoring_function():
    """The benchmark and the ES trainer score loops through ``agents.bench.scores`` (the ES used its own
    reversal counter with another dead band, and the true level's IAE)."""
    src = _sources()
    users = find_loop_scorers(src)
    assert LOOP_SCORES in users and "valve_gym/agents/es.py" in users
    es = next(t for p, t in src if p == "valve_gym/agents/es.py")
    assert not any(isinstance(n, ast.ClassDef) and "Reversal" in n.name for n in ast.walk(es)), \
        "the ES trainer counts reversals with the benchmark's valve_motion"
    calls = {p for p, t in src for n in ast.walk(t)
             if isinstance(n, ast.Call) and _called(n) == "reversal_counts"}
    assert calls == {LOOP_SCORES}
