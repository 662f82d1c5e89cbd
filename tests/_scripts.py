"""Loading the repository's scripts (files outside the ``pilco`` package, such as
``notebooks/execute.py`` and ``results/build.py``) as modules in the tests."""
from __future__ import annotations

import importlib.util
import sys


def load_script(name: str, path) -> object:
    """The module of the Python file ``path``, registered under no package; no
    ``__pycache__`` is written next to the script."""
    spec = importlib.util.spec_from_file_location(name, str(path))
    module = importlib.util.module_from_spec(spec)
    dont_write = sys.dont_write_bytecode
    sys.dont_write_bytecode = True
    try:
        spec.loader.exec_module(module)
    finally:
        sys.dont_write_bytecode = dont_write
    return module
