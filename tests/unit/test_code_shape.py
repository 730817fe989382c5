"""The shape the code keeps (issue 37): no import cycle between modules, no module importing
another's private name (besides the extension hmlvs._core), no source file over 600 lines and
no Python function over 80 lines outside the paper's studies."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "python" / "hmlvs"
MAX_FILE_LINES = 600
MAX_FUNCTION_LINES = 80


def _modules() -> dict[str, Path]:
    out = {}
    for p in PACKAGE.rglob("*.py"):
        parts = p.relative_to(PACKAGE.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = p
    return out


def _imports(name: str, path: Path, modules: dict[str, Path]) -> list[tuple[str, str]]:
    """(module imported, name imported) of every ``from ... import`` in ``path``, function
    bodies included."""
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[:len(package.split(".")) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            for a in node.names:
                full = f"{target}.{a.name}"
                out.append((full, "") if full in modules else (target, a.name))
    return [(t, n) for t, n in out if t in modules and t != name]


def test_no_import_cycle():
    modules = _modules()
    graph = {m: {t for t, _ in _imports(m, p, modules)} for m, p in modules.items()}
    state: dict[str, int] = {}  # 1: on the path, 2: done

    def visit(m: str, path: list[str]) -> None:
        state[m] = 1
        for t in sorted(graph[m]):
            if state.get(t) == 1:
                raise AssertionError("import cycle: " + " -> ".join(path + [m, t]))
            if t not in state:
                visit(t, path + [m])
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [])


def test_no_private_name_imported_across_modules():
    modules = _modules()
    bad = [(m, t, n) for m, p in modules.items() for t, n in _imports(m, p, modules)
           if n.startswith("_") and not n.startswith("__") and not t.endswith("._core")
           and t != "hmlvs"]
    assert not bad, bad


def test_no_source_file_over_600_lines():
    files = [p for d in ("python", "cpp", "bench", "examples", "tests") for p in
             (ROOT / d).rglob("*") if p.suffix in (".py", ".cpp", ".h")
             and "data" not in p.relative_to(ROOT).parts]
    long = {str(p.relative_to(ROOT)): n for p in files
            if (n := p.read_text().count("\n")) > MAX_FILE_LINES}
    assert not long, long


def test_no_python_function_over_80_lines_outside_the_papers_studies():
    long = []
    for p in PACKAGE.rglob("*.py"):
        if "paper" in p.relative_to(PACKAGE).parts:
            continue
        for node in ast.walk(ast.parse(p.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > MAX_FUNCTION_LINES:
                    long.append((str(p.relative_to(PACKAGE)), node.name, n))
    assert not long, long
