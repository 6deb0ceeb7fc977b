"""The code reproduces the golden campaign of bba2fd8 bit for bit (``tests/data/golden-literal``).

Every group x 200 encounters, seed 4242, reading ``literal``, produced by the code at bba2fd8 (see
``tests/data/README.md``). The campaign is run again from the configuration stored in its
``campaign.json`` and compared with :func:`daa_sil.study.campaign_compare.compare_dirs`, the same
comparison as ``benchmarks/compare_campaigns.py``. numpy's SIMD math may differ between CPUs, so
this runs in CI on CI's own CPU. With one worker the seven groups run as two batched tasks, so the
group batching of the campaign runner is part of what is checked.
"""

from __future__ import annotations

import json
from pathlib import Path

from daa_sil.study.campaign import run_campaign
from daa_sil.study.campaign_compare import compare_dirs
from daa_sil.study.campaign_config import CampaignConfig

GOLDEN = Path(__file__).resolve().parent / "data" / "golden-literal"


def test_golden_campaign_is_reproduced_exactly(tmp_path):
    stored = json.loads((GOLDEN / "campaign.json").read_text())["config"]
    cfg = CampaignConfig.from_dict(stored, str(GOLDEN / "campaign.json"))
    assert stored["reading"] == "literal"  # bba2fd8's name; read today as the alias of "extended"
    assert (cfg.n_encounters, cfg.seed, cfg.reading, len(cfg.groups)) == (200, 4242, "extended", 7)
    summary = run_campaign(cfg, tmp_path / "run", workers=1, progress=False)
    assert summary.chunks_run == 7
    res = compare_dirs(GOLDEN, tmp_path / "run")
    assert res.identical, "\n".join(res.differences)
    assert len(res.tables) == 1 + 2 * 7  # the encounter set and both tables of every group were compared
