"""What the before/after benchmarks share: running one of them as a child process under the
code of a given checkout, on one thread as a ``make paper`` worker runs."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any


def child_result(script: str, code: Path, args: list[str]) -> dict[str, Any]:
    """The JSON object ``script`` prints last when run as ``script --child ARGS`` with the
    code at ``code`` (``PYTHONPATH``) on one thread."""
    env = dict(os.environ, PYTHONPATH=str(code), OMP_NUM_THREADS="1",
               OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    out = subprocess.run([sys.executable, script, "--child", *args], env=env, check=True,
                         capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def checkouts(before: Path | None) -> dict[str, Path]:
    """``{"after": this checkout}``, and ``"before": before`` when given."""
    here = Path(__file__).resolve().parents[1]
    return {"after": here} | ({"before": before.resolve()} if before else {})
