"""tms-launch --record: where the recorder node goes in the launch (after the first process, so a reverse shutdown
stops it last but one), its parameters, and the refusals (existing directory, --containers), nothing started."""

from __future__ import annotations

from pathlib import Path

import pytest

from tms_common.config import repo_root
from tms_common.errors import ConfigError
from tms_launch.launch_file import RECORDER_NAME, parse_launch_file, processes, with_recorder
from tms_launch.launcher import main

PAPER = repo_root() / "config/launch/paper_experiment.yaml"


def test_recorder_is_the_second_process(tmp_path: Path) -> None:
    launch = with_recorder(parse_launch_file(PAPER), tmp_path / "bag")
    composed = [p.name for p in processes(launch, "composed")]
    assert composed[:2] == ["plant", RECORDER_NAME] and composed.count(RECORDER_NAME) == 1
    per_node = [p.name for p in processes(launch, "per-node")]
    assert per_node.index(RECORDER_NAME) == 3  # after sim_plant and both converters (the plant container)
    spec = next(n for n in launch.nodes if n.name == RECORDER_NAME)
    assert spec.parameters == {"use_sim_time": True, "output": str(tmp_path / "bag")}
    assert spec.container is None and spec.required and spec.stop_grace_s > 2.5
    assert not (tmp_path / "bag").exists()  # the recorder creates it when it starts


def test_record_refusals(tmp_path: Path, capsys) -> None:
    with pytest.raises(ConfigError, match="exists already"):
        with_recorder(parse_launch_file(PAPER), tmp_path)
    with pytest.raises(ConfigError, match="does not exist"):
        with_recorder(parse_launch_file(PAPER), tmp_path / "a" / "b")
    assert main([str(PAPER), "--record", str(tmp_path), "--list"]) == 2
    assert f"{tmp_path} exists already" in capsys.readouterr().err
    assert main([str(PAPER), "--record", str(tmp_path / "x"), "--containers", "plant", "--list"]) == 2
    assert "--record with --containers" in capsys.readouterr().err
    assert main([str(PAPER), "--record", str(tmp_path / "x"), "--list", "--layout", "composed"]) == 0
    assert f"{RECORDER_NAME}\tnode\t/{RECORDER_NAME}" in capsys.readouterr().out
