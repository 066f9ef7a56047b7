"""Make cm_helpers importable: the test plugins are loaded by `module:Class` strings
(e.g. `cm_helpers:CountingController`), so they need a real top-level module name."""
import sys
from pathlib import Path

HERE = str(Path(__file__).resolve().parent)
if HERE not in sys.path:
    sys.path.insert(0, HERE)
