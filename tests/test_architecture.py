"""The package's architecture holds: no import cycle between jaxlink's modules, experiments and
benchmarks use only the public API, and the public names exist."""

import ast
import pathlib
import re

ROOT = pathlib.Path(__file__).resolve().parents[1]
PKG = ROOT / "jaxlink"


def _module_of(path: pathlib.Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _imports(path: pathlib.Path) -> set:
    """Every jaxlink module imported anywhere in the file (module level or inside functions)."""
    mod = _module_of(path)
    is_pkg = path.name == "__init__.py"
    base = mod.split(".") if is_pkg else mod.split(".")[:-1]
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                target = ".".join(base[: len(base) - node.level + 1] + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] != "jaxlink":
                continue
            for alias in node.names:  # `from pkg import module` imports the module
                sub = f"{target}.{alias.name}"
                out.add(sub if (PKG.parent / (sub.replace(".", "/") + ".py")).exists()
                        or (PKG.parent / sub.replace(".", "/")).is_dir() else target)
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names if a.name.split(".")[0] == "jaxlink")
    out.discard(mod)
    return out


def test_no_import_cycle_inside_the_package():
    graph = {_module_of(p): _imports(p) for p in PKG.rglob("*.py")}
    # a package's __init__ re-exports its modules: importing `jaxlink.x` from inside `jaxlink.x.y`
    # is the edge that makes a cycle, so every edge counts
    state: dict = {}
    stack: list = []

    def visit(m):
        state[m] = 1
        stack.append(m)
        for n in sorted(graph.get(m, ())):
            if n not in graph:
                continue
            if state.get(n) == 1:
                raise AssertionError("import cycle: " + " -> ".join(stack[stack.index(n):] + [n]))
            if n not in state:
                visit(n)
        stack.pop()
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m)


def test_experiments_and_benchmarks_use_only_the_public_api():
    private = re.compile(r"(jaxlink|jl)(\.[a-z_0-9]+)*\._[a-z]|from jaxlink(\.[a-z_0-9]+)*\._")
    deep = re.compile(r"(from|import) jaxlink\.(?!optimize\b|cam\b|synthesis\b)[a-z_]+")
    bad = []
    for folder in ("experiments", "benchmarks"):
        for path in (ROOT / folder).rglob("*.py"):
            for i, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
                sub = re.search(r"jaxlink\.(optimize|cam|synthesis)\.[a-z_]+ import", line)
                if private.search(line) or deep.search(line) or sub:
                    bad.append(f"{path.relative_to(ROOT)}:{i}: {line.strip()}")
    assert not bad, "\n".join(bad)


def test_public_names():
    import jaxlink as jl
    import jaxlink.cam
    import jaxlink.optimize

    for name in ("load", "loads", "Mechanism", "solve", "solve_path", "Solution", "RESULTS", "transfer",
                 "time_derivatives", "reactions", "Reactions", "NewtonOptions", "MechanismError"):
        assert hasattr(jl, name), name
    assert jaxlink.optimize.__name__ and jaxlink.cam.__name__
