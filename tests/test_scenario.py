"""Scenario schema: strict validation naming file/line/field, shipped files, conversion to encounters."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from daa_sil.errors import FileFormatError
from daa_sil.sil.scenario import (dump_scenario, encounter_set, load_scenario, parse_scenario, save_scenario,
                              scenario_from_dict)

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = sorted((ROOT / "scenarios").glob("*.yaml"))

BASE = """\
name: t
ownship: {alt_m: 1000, gs_mps: 55, track_deg: 0}
intruders:
  - cpa: {angle_deg: 180, hmd_m: 100, t_cpa_s: 60, gs_mps: 55}
link: {up: "const:4"}
expect: {lowc: false}
"""


def _err(text: str) -> str:
    with pytest.raises(FileFormatError) as ei:
        parse_scenario(text, "s.yaml")
    return str(ei.value)


def test_unknown_key_names_file_line_field():
    msg = _err(BASE.replace("gs_mps: 55}\nlink", "gs_mps: 55, colour: red}\nlink"))
    assert msg.startswith("s.yaml:4: intruders[0].cpa.colour: unknown key")


def test_wrong_type_names_file_line_field():
    msg = _err(BASE.replace("alt_m: 1000", "alt_m: high"))
    assert msg.startswith("s.yaml:2: ownship.alt_m: must be a number")


def test_missing_field_names_file_line_field():
    msg = _err(BASE.replace("track_deg: 0", "vs_mps: 0"))
    assert msg.startswith("s.yaml:2: ownship.track_deg: missing required field")


def test_out_of_range_names_file_line_field_and_value():
    msg = _err(BASE.replace("hmd_m: 100", "hmd_m: 9000"))
    assert msg == "s.yaml:4: intruders[0].cpa.hmd_m: must be within [-5000, 5000], got 9000"


def test_bad_delay_spec_and_bad_decision_name():
    assert _err(BASE.replace('"const:4"', '"const:40"')).startswith("s.yaml:5: link.up:")
    assert _err(BASE.replace("lowc: false", "decisions_include: [hover]")).startswith(
        "s.yaml:6: expect.decisions_include[0]: must be one of")


def test_duplicate_key_bool_as_number_and_both_placements():
    assert "duplicate key" in _err(BASE + "name: again\n")
    assert _err(BASE.replace("alt_m: 1000", "alt_m: true")).startswith("s.yaml:2: ownship.alt_m: must be a number")
    both = BASE.replace("  - cpa:", "  - initial: {x_m: 0, y_m: 5000, alt_m: 1000, gs_mps: 50, track_deg: 180}\n    cpa:")
    assert "exactly one of 'initial'" in _err(both)


def test_scripted_pilot_rules():
    assert "pilot.commands: missing required field" in _err(BASE + "pilot: {mode: scripted}\n")
    assert "only allowed with mode: scripted" in _err(BASE + "pilot: {commands: [{t_s: 1, track_deg: 5}]}\n")
    bad_order = BASE + "pilot: {mode: scripted, commands: [{t_s: 5, track_deg: 5}, {t_s: 5, vs_mps: 1}]}\n"
    assert "must be later than the previous command" in _err(bad_order)
    sc = parse_scenario(BASE + "pilot: {mode: scripted, commands: [{t_s: 5, track_deg: 5}, {t_s: 9, vs_mps: 1}]}\n")
    first, second = sc.pilot.commands
    assert (first.t_s, first.until_s, second.until_s) == (5.0, 9.0, 240.0)  # until next, then the end
    assert math.isnan(first.vs_mps) and second.vs_mps == 1.0


def test_not_yaml_and_missing_file(tmp_path):
    assert _err("a: [1, 2").startswith("s.yaml:")
    with pytest.raises(FileFormatError, match="not found"):
        load_scenario(tmp_path / "nope.yaml")


def test_defaults_and_group_policy():
    sc = parse_scenario(BASE.replace("expect: {lowc: false}\n", "allocation: {group: B-2}\n"))
    assert sc.seed == 1 and sc.duration_s == 240 and sc.thresholds == "do365"
    assert (sc.allocation.wait, sc.allocation.blending) == ("none", False)  # baseline group
    assert sc.link.down is None and sc.n_steps == 240


def test_save_load_round_trip(tmp_path):
    sc = parse_scenario(BASE)
    p = save_scenario(sc, tmp_path / "x.yaml")
    assert load_scenario(p) == sc
    assert scenario_from_dict(sc.to_dict()) == sc
    assert "angle_deg: 180.0" in dump_scenario(sc)


@pytest.mark.parametrize("path", SCENARIOS, ids=[p.stem for p in SCENARIOS])
def test_shipped_scenarios_are_valid_and_say_what_they_expect(path):
    sc = load_scenario(path)
    e = sc.expect
    assert e.lowc is not None or e.nmac is not None or e.decisions_include, "every scenario states an outcome"
    es = encounter_set(sc)
    assert es.intr.shape == (1, len(sc.intruders))


def test_required_scenarios_exist():
    names = {p.stem for p in SCENARIOS}
    assert {"head_on", "crossing_left", "crossing_right", "overtaking", "climbing", "two_intruders",
            "pilot_unsafe_blend", "link_loss", "long_delay"} <= names


def test_encounter_set_head_on_geometry_by_hand():
    # head-on, both 55 m/s, CPA 0 m at 60 s: the intruder starts 110 m/s * 60 s = 6600 m ahead, flying south
    sc = parse_scenario(BASE.replace("hmd_m: 100", "hmd_m: 0"))
    es = encounter_set(sc)
    assert es.intr.y[0, 0] == pytest.approx(6600.0, abs=1e-6)
    assert es.intr.x[0, 0] == pytest.approx(0.0, abs=1e-6)
    assert es.intr.trk[0, 0] == pytest.approx(math.pi)


def test_encounter_set_initial_state_and_script():
    text = BASE.replace("  - cpa: {angle_deg: 180, hmd_m: 100, t_cpa_s: 60, gs_mps: 55}",
                        "  - initial: {x_m: 3000, y_m: 4000, alt_m: 900, gs_mps: 40, track_deg: 270}\n"
                        "    maneuvers: [{start_s: 10, end_s: 20, turn_rate_dps: -2}]")
    es = encounter_set(parse_scenario(text))
    assert (es.intr.x[0, 0], es.intr.y[0, 0], es.intr.z[0, 0]) == (3000.0, 4000.0, 900.0)
    turn, _, _ = es.intruder_controls(15.0)
    assert turn[0, 0] == pytest.approx(np.radians(-2.0))
    assert es.intruder_controls(20.0)[0][0, 0] == 0.0  # the segment is [start, end)
