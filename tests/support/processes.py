"""Running code in a fresh interpreter, for what one test process cannot show (imports, registration)."""

from __future__ import annotations

import subprocess
import sys


def run_python(code: str, timeout: float = 120, **kwargs) -> str:
    """Run ``code`` with ``python -c``; assert it exits 0 (showing its stderr otherwise), return its stdout.

    ``kwargs`` go to ``subprocess.run`` (``cwd``, ``env``)."""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=timeout, **kwargs)
    assert out.returncode == 0, out.stderr
    return out.stdout
