"""The tables of the command reference (docs/usage.md) say what the commands do: the preset each
input flies when none is named, and the shim's options (``--listen-vehicle`` / ``--listen-gcs`` are its sockets; ``--vehicle`` /
``--gcs`` name its peers). Each claim is checked against what the command records or parses."""

from __future__ import annotations

import contextlib
import io
import json
import re
from pathlib import Path

from daa_sil.cli import main

ROOT = Path(__file__).resolve().parents[1]
USAGE = (ROOT / "docs" / "usage.md").read_text(encoding="utf-8")  # the command and preset tables


def preset_rows() -> dict[str, str]:
    """``{preset: its row's first cell}`` of the threshold-preset table."""
    rows = {}
    for line in USAGE.splitlines():
        m = re.match(r"\| `(\w+)`([^|]*)\|", line)
        if m and m.group(1) in ("do365", "paper", "daidalus"):
            rows.setdefault(m.group(1), m.group(2).strip())
    return rows


def cli_json(argv) -> dict:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main([str(a) for a in argv]) == 0
    return json.loads(out.getvalue())


def test_the_preset_table_names_the_default_of_each_input():
    from daa_sil.config.settings import PRESET, STANDARD_PRESET
    from daa_sil.study.campaign.config import CampaignConfig

    rows = preset_rows()
    assert all("(default)" != cell for cell in rows.values()), rows  # a bare "default" hides who defaults to it
    campaigns = next(p for p, cell in rows.items() if "campaigns" in cell)
    scenarios = next(p for p, cell in rows.items() if "scenario files" in cell)
    assert campaigns == CampaignConfig().preset == PRESET.default
    assert scenarios == STANDARD_PRESET.default
    pair = ["--own", "0,0,1000,0,55,0", "--intruder", "0,6000,1000,0,-100,0", "--json"]
    for command in ("geometry", "daa"):
        named = next(p for p, cell in rows.items() if f"`{command}`" in cell)
        assert cli_json([command, *pair])["preset"] == named, command


def test_the_preset_table_default_of_waitmap_build(tmp_path):
    from daa_sil.waitmap.family_files import load_family

    named = next(p for p, cell in preset_rows().items() if "`waitmap build`" in cell)
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["waitmap", "build", "--grid", "paper,dx=6,dy=6,dh=3,vi=3,vh=3,theta=4", "--turn-rates", "0",
                     "--out", str(tmp_path / "m")]) == 0
    assert load_family(tmp_path / "m").params.preset == named


def test_the_shim_row_shows_the_options_that_set_its_sockets():
    from daa_sil.commands.shim import build_parser

    row = next(line for line in USAGE.splitlines() if line.startswith("| `daa-sil shim"))
    usage = row.split("`")[1]
    options = re.findall(r"--[a-z][a-z-]*", usage)
    known = {o for a in build_parser()._actions for o in a.option_strings}
    assert set(options) <= known, set(options) - known
    assert usage.index("--listen-vehicle") < usage.index("[--vehicle")  # the sockets first, the peers optional
    assert "--listen-gcs" in usage and "[--gcs" in usage
