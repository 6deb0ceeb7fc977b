"""The code reproduces a golden campaign bit for bit (``tests/data/golden-literal*``).

Every group x 200 encounters, seed 4242, reading ``extended`` (formerly ``literal``), produced by the
code since one encounter's DAA numbers no longer depend on its batch (see ``tests/data/README.md``).
The campaign is run again from the configuration stored in its ``campaign.json`` and compared with
:func:`daa_sil.study.campaign.compare.compare_dirs`, the same comparison as
``benchmarks/compare_campaigns.py``. With one worker the seven groups run as batched tasks, so the
group batching of the campaign runner is part of what is checked.

numpy's SIMD math differs between CPU classes (its dispatched transcendental functions, which also
build the wait maps), so the same code gives different bits on different CPUs. Each golden is
produced on one CPU class (``tests/data/README.md`` lists them). The run must be identical to one of
them, every column; on a CPU class with no golden the test fails and says how to produce one.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from daa_sil.study.campaign.run import run_campaign
from daa_sil.study.campaign.compare import compare_dirs
from daa_sil.study.campaign.config import CampaignConfig

DATA = Path(__file__).resolve().parent / "data"
GOLDENS = sorted(p for p in DATA.glob("golden-literal*") if p.is_dir())


def numpy_simd() -> str:
    """This CPU's numpy SIMD targets that are found (for the failure message)."""
    try:
        from numpy._core import _multiarray_umath as mu
        found = [t for t in mu.__cpu_dispatch__ if mu.__cpu_features__.get(t)]
        return f"baseline {mu.__cpu_baseline__}, dispatch targets found {found} (numpy {np.__version__})"
    except (ImportError, AttributeError):
        return f"numpy {np.__version__}"


def test_goldens_share_one_configuration():
    configs = [json.loads((g / "campaign.json").read_text())["config"] for g in GOLDENS]
    assert len(GOLDENS) >= 1 and all(c == configs[0] for c in configs)


def test_golden_campaign_is_reproduced_exactly(tmp_path):
    stored = json.loads((GOLDENS[0] / "campaign.json").read_text())["config"]
    cfg = CampaignConfig.from_dict(stored, str(GOLDENS[0] / "campaign.json"))
    assert stored["reading"] == "extended"  # (formerly "literal", still accepted as its alias)
    assert (cfg.n_encounters, cfg.seed, cfg.reading, len(cfg.groups)) == (200, 4242, "extended", 7)
    summary = run_campaign(cfg, tmp_path / "run", workers=1, progress=False)
    assert summary.chunks_run == 7
    # columns written since bba2fd8 are listed apart; every column the golden has must match bit for bit
    results = {g.name: compare_dirs(g, tmp_path / "run", allow_added=True) for g in GOLDENS}
    from daa_sil.study.simulation.fasttime_results import EXTRA_COLUMNS, SUPERSEDED_COLUMNS

    for res in results.values():
        assert len(res.tables) == 1 + 2 * 7  # the encounter set and both tables of every group were compared
        assert {x.split(": ", 1)[1] for x in res.added} == set(EXTRA_COLUMNS + SUPERSEDED_COLUMNS)
    matched = [name for name, res in results.items() if res.identical]
    report = "\n".join(f"{name}: " + "; ".join(res.differences) for name, res in results.items())
    assert matched, (f"the run is identical to none of the goldens on this CPU ({numpy_simd()}):\n"
                     f"{report}\nIf this is a CPU class without a golden, add one for it "
                     "(tests/data/README.md says how).")
