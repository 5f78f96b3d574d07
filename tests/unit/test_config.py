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
