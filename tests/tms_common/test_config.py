"""YAML loading with locations."""

import pytest

from tms_common.config import load_yaml_text
from tms_common.errors import ConfigError


def test_line_of_nested_keys():
    data, where = load_yaml_text("a: 1\nb:\n  - x: 2\n    y: 3\n", "f.yaml")
    assert data == {"a": 1, "b": [{"x": 2, "y": 3}]}
    assert where.line_of(("b", 0, "y")) == 4
    assert where.line_of(("b", 0, "missing")) == 3
    assert str(where.error(("a",), "bad")) == "f.yaml:1: bad"


def test_malformed_yaml_names_file_and_line():
    with pytest.raises(ConfigError, match=r"^f.yaml:4: malformed YAML: .*flow sequence at line 3"):
        load_yaml_text("a: 1\nb: 2\nc: [1, 2\n", "f.yaml")


def test_yaml_limits_refuse_bombs_and_depth_naming_file_and_line(tmp_path):
    from tms_common.config import MAX_YAML_ALIASES, MAX_YAML_DEPTH, MAX_YAML_NODES

    # 7 levels of 9 aliases: 4.8 million values once expanded, from under 300 bytes
    rows = ['a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]']
    rows += [f"{n}: &{n} [" + ",".join([f"*{p}"] * 9) + "]" for p, n in zip("abcdef", "bcdefg", strict=True)]
    with pytest.raises(ConfigError, match=rf"^bomb.yaml:6: YAML expands to more than {MAX_YAML_NODES} values"):
        load_yaml_text("\n".join(rows) + "\n", "bomb.yaml")
    with pytest.raises(ConfigError, match=rf"^deep.yaml:1: YAML nested deeper than {MAX_YAML_DEPTH} levels"):
        load_yaml_text("[" * 5000 + "]" * 5000, "deep.yaml")
    with pytest.raises(ConfigError, match=rf"^many.yaml:2: more than {MAX_YAML_ALIASES} YAML aliases"):
        load_yaml_text("x: &x 1\nl: [" + ",".join(["*x"] * (MAX_YAML_ALIASES + 1)) + "]\n", "many.yaml")
    # within the limits aliases still work as YAML says (a config may share a block)
    data, _ = load_yaml_text("base: &b {k: 1}\nuse: *b\n", "ok.yaml")
    assert data["use"] == {"k": 1}


def test_load_yaml_names_a_file_that_is_not_utf8(tmp_path):
    from tms_common.config import load_yaml

    f = tmp_path / "site.yaml"
    f.write_bytes(b"name: ok\nnote: caf\xe9\n")
    with pytest.raises(ConfigError, match=rf"^{f}:2: not UTF-8 text: byte 0xe9 at byte offset 18$"):
        load_yaml(f)


def test_every_project_config_file_is_within_the_yaml_limits():
    # the limits must never refuse the project's own files (every node and launch file reads them)
    from tms_common.config import load_yaml, repo_root

    files = sorted((repo_root() / "config").rglob("*.yaml"))
    assert len(files) > 10
    for f in files:
        load_yaml(f)
