"""The package's layers point one way: each module imports only from its own layer and the layers
before it, function-level imports included, and no two modules import each other in a cycle."""

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"
# the order of epa/__init__.py's docstring; a top-level module is a layer of its own
LAYERS = (
    "core",
    "steps",
    "metrics",
    "readers",
    "artifacts",
    "simulate",
    "outputs",
    "workflow",
    "evo",
    "rpg",
    "api",
    "cli",
)


def _modules() -> dict[str, Path]:
    out = {}
    for f in sorted((SRC / "epa").rglob("*.py")):
        parts = f.relative_to(SRC).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = f
    return out


def _imports(path: Path, modules) -> set[str]:
    """Every epa module this file imports, at any depth of the code."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            # `from pkg import mod` imports pkg.mod; `from mod import name`, mod
            names = [
                f"{node.module}.{a.name}" if f"{node.module}.{a.name}" in modules else node.module
                for a in node.names
            ]
        else:
            continue
        for name in names:
            while name and name not in modules:
                name = name.rpartition(".")[0]
            if name.startswith("epa."):
                found.add(name)
    return found


def _layer(module: str) -> int:
    part = module.split(".")[1]
    assert part in LAYERS, f"{module}: not in a layer of tests/test_layers.py"
    return LAYERS.index(part)


GRAPH = {m: _imports(f, _modules()) - {m} for m, f in _modules().items() if m != "epa"}


def test_every_import_points_to_the_same_or_an_earlier_layer():
    upward = [
        f"{m} -> {dep}"
        for m, deps in sorted(GRAPH.items())
        for dep in sorted(deps)
        if dep != "epa" and _layer(dep) > _layer(m)
    ]
    assert not upward, "imports that point up:\n" + "\n".join(upward)


def test_no_import_cycles():
    def cycle_from(start):
        stack = [(start, [start])]
        while stack:
            node, path = stack.pop()
            for dep in sorted(GRAPH.get(node, ())):
                if dep == start:
                    return path
                if dep not in path and not start.startswith(dep + "."):
                    stack.append((dep, path + [dep]))
        return None

    cycles = {tuple(c) for m in GRAPH if (c := cycle_from(m))}
    assert not cycles, "import cycles:\n" + "\n".join(" -> ".join(c) for c in sorted(cycles))


def test_the_test_sees_function_level_imports(tmp_path):
    probe = tmp_path / "probe.py"
    probe.write_text("def f():\n    from epa.workflow import chain\n")
    assert "epa.workflow.chain" in _imports(probe, _modules())
