"""The design seeds (config/seeds/design_trench.yaml, design_embankment.yaml): each design goes into the store's
collection ``design`` beside its task and record; a seed with a bad design stores nothing (both backends)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.rosproc import ROOT
from tms_db import DESIGN_COLLECTION, Store, ValidationError, get_design, list_designs
from tms_db.cli import seed
from tms_rp.excavation.design import Design


def test_the_design_trench_seed_puts_its_design(store: Store) -> None:
    n_tasks, n_params = seed(store, ROOT / "config" / "seeds" / "design_trench.yaml")
    # the two bases' poses and design records, the two via poses round the trench, and the run's blackboard (the
    # supervisor writes CONTINUE_FLG)
    assert (n_tasks, n_params) == (1, 7)
    assert store.get_parameter("global_blackboard", "DESIGN_BLACKBOARD")["CONTINUE_FLG"] is True
    assert store.get_parameter("zx200", "design_trench_base_north")["y"] == 8.4
    job = store.get_parameter("zx200", "design_trench_south")
    design = Design.from_dict(get_design(store, job["design"]))
    assert design.kind == "trench" and design.params["depth"] == 0.5 and design.params["width"] == 1.0
    seed(store, ROOT / "config" / "seeds" / "design_trench.yaml")  # idempotent: no second version
    assert len(store.find_data(DESIGN_COLLECTION, 3040, name=job["design"])) == 1


def test_the_design_embankment_seed_puts_its_design(store: Store) -> None:
    assert seed(store, ROOT / "config" / "seeds" / "design_embankment.yaml") == (1, 2)
    job = store.get_parameter("zx200", "design_embankment_job")
    design = Design.from_dict(get_design(store, job["design"]))
    assert design.kind == "embankment" and (design.params["height"], design.params["crest_width"]) == (0.4, 1.0)
    assert 'record_name="design_embankment_job"' in store.get_task(36)["task_sequence"]


def test_a_seed_with_a_bad_design_stores_nothing(store: Store, tmp_path: Path) -> None:
    f = tmp_path / "s.yaml"
    f.write_text("parameters:\n  - model_name: m\n    record_name: r\n    a: 1\n"
                 "designs:\n  - name: x\n    kind: pond\n")
    with pytest.raises(ValidationError, match=r"s.yaml:6: design 'x': kind must be one of"):
        seed(store, f)
    assert store.list_parameters() == [] and list_designs(store) == []
