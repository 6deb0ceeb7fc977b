"""``daa-sil daa`` command: JSON content for a hand-worked encounter and one-line usage errors."""

import json

from daa_sil.cli import main


def test_daa_json_head_on(capsys):
    # intruder passing 500 m to the right, head-on, 6 km: warning; the left resolution is preferred
    rc = main(["daa", "--own", "0,0,1000,0,55,0", "--intruder", "500,6000,1000,0,-55,0", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert rc == 0 and out["alert_levels"] == ["warning"] and out["preset"] == "do365"
    trk = out["bands"]["trk_deg"]
    assert any(reg == "none" and lo <= 270 <= hi for lo, hi, reg in trk if lo <= hi)  # due west is free
    assert out["daa_command"]["direction"] == "left" and out["daa_command"]["axis"] == "horizontal"
    lo = out["resolutions"]["horizontal"]["lo_deg"]
    assert 270 < lo < 360


def test_daa_usage_errors(capsys):
    assert main(["daa", "--own", "0,0,1000,0,0,0", "--intruder", "1,2,3,4,5,6"]) == 2
    assert "non-zero horizontal velocity" in capsys.readouterr().err
    assert main(["daa", "--own", "0,0,1000,0,55,0", "--intruder", "1,2,3", "--preset", "do365"]) == 2
    assert "--intruder needs 6" in capsys.readouterr().err
