"""The lint configuration (pyproject.toml [tool.ruff]) is what the code meets: ``ruff check`` passes on the tree."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_ruff_check_passes() -> None:
    ruff = Path(sys.executable).with_name("ruff")
    assert ruff.exists(), f"ruff is a test dependency (pyproject.toml [project.optional-dependencies] test): {ruff}"
    done = subprocess.run([str(ruff), "check", "--no-cache", "."], cwd=ROOT, capture_output=True, text=True,
                          timeout=300, check=False)
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-2000:]
