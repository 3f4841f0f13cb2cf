"""Every module of the package imports without the optional extras (the doctests import them all)."""

from __future__ import annotations

import subprocess
import sys

#: Optional extras (pyproject: usd, fast, baselines) and optional helpers; none may be imported
#: when a module is.
OPTIONAL = ("pxr", "embreex", "open3d", "imageio", "imageio_ffmpeg")

SCRIPT = f"""
import importlib, importlib.abc, pkgutil, sys

class Missing(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in {OPTIONAL!r}:
            raise ImportError(f"{{name}} is not installed (blocked by the test)")
        return None

sys.meta_path.insert(0, Missing())
import fourd

for module in pkgutil.walk_packages(fourd.__path__, "fourd."):
    if module.name != "fourd.__main__":
        importlib.import_module(module.name)
print("ok")
"""


def test_every_module_imports_without_the_optional_extras():
    done = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr[-2000:]
