"""The daa-sil MAVLink dialect: ``daa_sil.xml`` (source of truth) and the generated ``daa_sil.py``.

``daa_sil.xml`` includes ``common.xml``; mavgen resolves includes relative to the XML file, so
``common.xml``, ``standard.xml`` and ``minimal.xml`` (copied from pymavlink 2.4.50
``dialects/v20/``) sit beside it. The generated module is committed; regenerate after editing the
XML with ``python -m daa_sil.link.dialect`` (a test checks that the committed module is current).
"""

from __future__ import annotations

import os
from pathlib import Path

DIALECT_DIR = Path(__file__).resolve().parent
XML_PATH = DIALECT_DIR / "daa_sil.xml"
MODULE_PATH = DIALECT_DIR / "daa_sil.py"


def generate(output: "str | os.PathLike" = MODULE_PATH, xml: "str | os.PathLike" = XML_PATH) -> Path:
    """Run pymavlink's mavgen (Python3, MAVLink 2.0, no lxml validation) on ``xml`` into ``output``."""
    from pymavlink.generator import mavgen

    out = Path(output)
    opts = mavgen.Opts(str(out), wire_protocol="2.0", language="Python3", validate=False)
    if not mavgen.mavgen(opts, [str(xml)]):
        raise RuntimeError(f"mavgen failed on {xml}")
    return out
