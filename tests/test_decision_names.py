"""The agent's decision names are defined once (``daa_sil.agent.decision.DECISION_NAMES``) and every schema
outside Python that spells them agrees with that definition: the MAVLink dialect's DAA_SIL_DECISION enum
(read from the XML, not through the generated module), the step-log schema in docs/architecture.md and
the scenario-file reference in ``daa_sil.sil.scenario.schema``."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from daa_sil import steplog
from daa_sil.agent import decision
from daa_sil.sil.scenario import schema as scenario_schema
from daa_sil.sil.scenario import scenario_from_dict
from daa_sil.errors import FileFormatError

ROOT = Path(__file__).resolve().parents[1]


def dialect_enum(name: str) -> list[tuple[str, str]]:
    """The entries of enum ``name`` in the dialect XML, by value: ``(name after the enum's prefix, lower
    case; description)``."""
    root = ET.parse(ROOT / "daa_sil" / "link" / "dialect" / "daa_sil.xml").getroot()
    enum = next(e for e in root.iter("enum") if e.get("name") == name)
    entries = sorted((int(e.get("value")), e.get("name")[len(name) + 1:].lower(), e.findtext("description").strip())
                     for e in enum.iter("entry"))
    assert [v for v, *_ in entries] == list(range(len(entries))), f"{name}: values are not 0..n-1"
    return [(n, d) for _, n, d in entries]


def test_python_readers_use_the_one_definition():
    assert steplog.DECISIONS is decision.DECISION_NAMES
    assert steplog.VOCAB["decision"] is decision.DECISION_NAMES
    assert scenario_schema.DECISIONS is decision.DECISION_NAMES
    for key, names in decision.CODE_NAMES.items():
        assert steplog.VOCAB[key] is names, key


def test_the_dialect_enum_spells_the_decision_names():
    entries = dialect_enum("DAA_SIL_DECISION")
    assert tuple(n for n, _ in entries) == decision.DECISION_NAMES
    assert tuple(d for _, d in entries) == decision.DECISION_NAMES  # the description is the step log's word
    assert tuple(n for n, _ in dialect_enum("DAA_SIL_AUTHORITY")) == decision.AUTHORITY_NAMES


def test_the_docs_list_the_decision_names():
    text = " ".join((ROOT / "docs" / "architecture.md").read_text().split())
    m = re.search(r"`decision` string \(one of `([^`]*)`\)", text)
    assert m, "docs/architecture.md no longer lists the step log's decision names"
    assert tuple(x.strip() for x in m.group(1).split(",")) == decision.DECISION_NAMES
    m = re.search(r"^Decision names: (.*)\.$", scenario_schema.__doc__, re.M)
    assert m and tuple(x.strip() for x in m.group(1).split(",")) == decision.DECISION_NAMES


def _scenario(names: list[str]) -> dict:
    return {"name": "t", "ownship": {"alt_m": 1500, "gs_mps": 55, "track_deg": 0},
            "intruders": [{"cpa": {"angle_deg": 180, "hmd_m": 0, "t_cpa_s": 60, "gs_mps": 60}}],
            "expect": {"decisions_include": names}}


def test_a_scenario_takes_every_decision_name_and_no_other():
    sc = scenario_from_dict(_scenario(list(decision.DECISION_NAMES)))
    assert tuple(sc.expect.decisions_include) == decision.DECISION_NAMES
    with pytest.raises(FileFormatError, match="decisions_include"):
        scenario_from_dict(_scenario(["hold"]))
