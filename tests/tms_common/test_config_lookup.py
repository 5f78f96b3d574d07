"""Config is found through the installed package, not the current directory (``ros2 run`` from anywhere)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tms_common import config
from tms_common.errors import ConfigError

ROOT = Path(__file__).resolve().parents[2]
VENV = ROOT / ".venv"


def _run_in(cwd: Path, code: str, **env: str) -> subprocess.CompletedProcess[str]:
    full = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    full.update(env)
    return subprocess.run([sys.executable, "-c", code], cwd=cwd, env=full, capture_output=True, text=True, timeout=60)


def test_node_config_lookup_from_another_directory(tmp_path: Path) -> None:
    # what the sensing node and the arm controller load at start-up, from a directory without config/
    code = (
        "from tms_common.config import data_root, config_path\n"
        "from tms_sp.config import load_sensing_config\n"
        "from tms_model.excavator.kinematics import load_kinematics\n"
        "cfg = load_sensing_config(); kin = load_kinematics('zx200')\n"
        "print(data_root()); print(config_path('site.yaml')); print(cfg.points['P1'].x, kin.kind)\n"
    )
    proc = _run_in(tmp_path, code, AMENT_PREFIX_PATH=str(VENV))
    assert proc.returncode == 0, proc.stderr
    root, site, last = proc.stdout.strip().splitlines()
    assert Path(site).is_file() and Path(site).name == "site.yaml"
    assert Path(root, "config").is_dir() and Path(root, "trees").is_dir()
    assert last == "1.2 zx200"


def test_share_directory_is_registered() -> None:
    share = VENV / "share" / config.DATA_PACKAGE
    assert (VENV / "share" / "ament_index" / "resource_index" / "packages" / config.DATA_PACKAGE).is_file()
    assert (share / "config" / "site.yaml").is_file()
    assert (share / "trees").is_dir()


def test_missing_config_names_every_place_searched(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(tmp_path / "empty-prefix"))
    monkeypatch.setattr(config, "repo_root", lambda: tmp_path / "no-checkout")
    with pytest.raises(ConfigError) as err:
        config.data_root.__wrapped__()
    message = str(err.value)
    assert "ament share directory of tms_common" in message
    assert str(tmp_path / "empty-prefix") in message
    assert str(tmp_path / "no-checkout" / "config") in message
