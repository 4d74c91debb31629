"""Importing raysort: the uncompiled source tree says what to do instead of failing obscurely."""
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.skipif(not (REPO / "setup.py").is_file(), reason="needs the source checkout")
def test_source_tree_without_extensions_gives_a_clear_message(tmp_path):
    """`python -c "import raysort"` in a checkout that was never built: one ImportError
    telling to `pip install .` and run elsewhere, not a circular-import error."""
    checkout = tmp_path / "checkout"
    shutil.copytree(REPO / "raysort", checkout / "raysort",
                    ignore=shutil.ignore_patterns("*.so", "*.pyd", "*.c", "__pycache__"))
    shutil.copy(REPO / "setup.py", checkout / "setup.py")
    proc = subprocess.run([sys.executable, "-c", "import raysort"], cwd=checkout,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 1
    last = proc.stderr.strip().splitlines()[-1]
    assert last.startswith("ImportError: this is raysort's source tree")
    assert "pip install ." in last and "another directory" in last
    assert "circular" not in proc.stderr


def test_installed_package_imports():
    proc = subprocess.run([sys.executable, "-c", "import raysort; print(raysort.Pipeline)"],
                          cwd="/", capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr


def _module_imports():
    """{module: the raysort modules it imports anywhere (function bodies included)}, read
    from the installed package's source; the package itself is not a node (``from raysort
    import isa`` imports the submodule)."""
    import ast

    import raysort

    root = Path(raysort.__file__).parent
    modules = {}
    for path in root.rglob("*.py"):
        parts = path.relative_to(root.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        modules[name] = path
    graph = {}
    for name, path in modules.items():
        edges = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("raysort"):
                for alias in node.names:
                    target = f"{node.module}.{alias.name}"
                    edges.add(target if target in modules else node.module)
            elif isinstance(node, ast.Import):
                edges.update(a.name for a in node.names if a.name in modules)
        graph[name] = {t for t in edges if t in modules and t != "raysort" and t != name}
    return graph


def test_no_import_circle():
    """No module of raysort imports, even lazily inside a function, a module that imports
    it back, directly or through others (the apps layer included: cli, bench, sweep)."""
    graph = _module_imports()
    assert {"raysort.cli", "raysort.pipeline", "raysort.distributed"} <= set(graph)
    done, path = set(), []

    def visit(name):
        if name in path:
            cycle = path[path.index(name):] + [name]
            pytest.fail("import circle: " + " -> ".join(cycle))
        if name in done:
            return
        path.append(name)
        for target in sorted(graph[name]):
            visit(target)
        path.pop()
        done.add(name)

    for name in sorted(graph):
        visit(name)


def test_the_circle_check_finds_a_circle(monkeypatch):
    """The check above can fail: a graph with a circle is reported."""
    monkeypatch.setitem(globals(), "_module_imports",
                        lambda: {"raysort.cli": {"raysort.pipeline"},
                                 "raysort.pipeline": {"raysort.distributed"},
                                 "raysort.distributed": {"raysort.pipeline"}})
    with pytest.raises(pytest.fail.Exception, match="import circle"):
        test_no_import_circle()
