"""Named readings of the paper's simulator: what each changes, recorded and checked on --resume."""

import json

import numpy as np
import pytest

from daa_sil.study.campaign import run_campaign
from daa_sil.study.campaign_config import CampaignConfig
from daa_sil.study.campaign_files import read_results
from daa_sil.cli import main
from daa_sil.errors import UsageError
from daa_sil.config.readings import READINGS, parse_reading_settings, reading_for
from daa_sil.geometry.units import FT


def test_bundles_and_what_they_change():
    lit = reading_for("literal")
    assert lit.encounter_overrides() == {} and lit.simulation_key() == ("metres", "corrective", True, None)
    p = lit.pilot_config()
    assert (p.alert_level_min, p.stream_level_min, p.stream_hold) == (2, None, True)
    feet = reading_for("feet")
    assert feet.encounter_overrides() == {"hmd_max_m": pytest.approx(838.2), "vmd_max_m": pytest.approx(278.892)}
    assert feet.pilot_config().alert_level_min == 1 and (feet.window, feet.received) == ("whole", "pilot+blend")
    assert reading_for("detection").pilot_config().stream_level_min == 0
    assert reading_for("no-hold").pilot_config().stream_hold is False
    # counting-only readings share the literal simulation
    assert reading_for("paper-counts").simulation_key() == lit.simulation_key()
    assert set(READINGS) >= {"literal", "paper-counts", "feet", "preventive", "detection", "no-hold"}
    with pytest.raises(UsageError, match="unknown reading 'x'"):
        reading_for("x")
    with pytest.raises(UsageError, match="units must be one of metres, feet"):
        reading_for("literal", units="yards")
    assert parse_reading_settings("units=feet, hold_commands=false") == {"units": "feet", "hold_commands": False}
    with pytest.raises(UsageError, match="KEY=VALUE"):
        parse_reading_settings("colour=blue")


def test_feet_reading_draws_cpas_inside_dmod_and_is_recorded(tmp_path):
    cfg = CampaignConfig(groups=("B-2",), n_encounters=40, seed=3, chunk_size=40, duration_s=240.0, reading="feet")
    run_campaign(cfg, tmp_path / "c", progress=False)
    meta = json.loads((tmp_path / "c" / "campaign.json").read_text())
    assert meta["config"]["reading"] == "feet" and meta["config"]["readings"]["units"] == "feet"
    from daa_sil.models.encounter_files import load_encounters

    es = load_encounters(tmp_path / "c" / "encounters.parquet")
    hmd, vmd = es.params["hmd_m"], es.params["vmd_m"]
    assert hmd.max() <= 2750 * FT and np.abs(vmd).max() <= 915 * FT
    assert hmd.max() > 0.5 * 2750 * FT  # drawn over the whole (feet) range, not squeezed
    # --resume with another reading is refused, naming the setting
    rc = main(["campaign", "run", "--out", str(tmp_path / "c"), "--resume", "--reading", "literal", "--no-progress"])
    assert rc == 2


def test_whole_encounter_counts_and_no_hold_reading(tmp_path):
    """Whole-encounter counts contain the active-phase ones; without 'hold' fewer commands arrive."""
    base = dict(groups=("ID-2",), n_encounters=60, seed=8, chunk_size=60, duration_s=240.0)
    run_campaign(CampaignConfig(**base), tmp_path / "hold", progress=False)
    run_campaign(CampaignConfig(**base, reading="no-hold"), tmp_path / "nohold", progress=False)
    a = read_results(tmp_path / "hold", "encounters")
    b = read_results(tmp_path / "nohold", "encounters")
    col = lambda t, k: np.asarray(t.column(k).to_numpy())  # noqa: E731
    assert np.all(col(a, "n_pilot_received_whole") >= col(a, "n_pilot_exec") + col(a, "n_blend") + col(a, "n_daa_override"))
    assert np.all(col(a, "n_pilot_exec_whole") >= col(a, "n_pilot_exec"))
    assert np.all(col(a, "n_pilot_exec_whole") <= col(a, "n_pilot_received_whole"))
    assert col(a, "n_pilot_received_whole").sum() > col(a, "n_pilot_received").sum()  # arrivals outside the phase
    assert col(b, "n_pilot_received_whole").sum() < col(a, "n_pilot_received_whole").sum()
