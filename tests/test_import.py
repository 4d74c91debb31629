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
