"""The committed generated dialect module is what mavgen makes from the committed XML."""

from __future__ import annotations

import shutil

from daa_sil.link import dialect
from daa_sil.link.dialect import daa_sil as mod


def test_regenerated_module_is_byte_identical(tmp_path):
    out = dialect.generate(tmp_path / "daa_sil.py")
    assert out.read_bytes() == dialect.MODULE_PATH.read_bytes(), \
        "daa_sil.xml changed without regenerating: run python -m daa_sil.link.dialect and commit daa_sil.py"


def test_generated_module_has_our_messages_in_the_private_range(tmp_path):
    ids = {name: getattr(mod, f"MAVLINK_MSG_ID_{name}") for name in
           ("DAA_BANDS", "ALLOCATION_DECISION", "SIM_TICK", "SIM_TICK_ACK", "PILOT_MANEUVER")}
    assert all(53000 <= i < 53100 for i in ids.values()) and len(set(ids.values())) == 5
    assert mod.MAVLINK_MSG_ID_HEARTBEAT == 0 and mod.WIRE_PROTOCOL_VERSION == "2.0"


def test_xml_change_changes_the_generated_module(tmp_path):
    """The regeneration check can fail: a one-field edit yields a different module."""
    for name in ("common.xml", "standard.xml", "minimal.xml"):
        shutil.copy(dialect.DIALECT_DIR / name, tmp_path / name)
    xml = dialect.XML_PATH.read_text().replace('name="sent">', 'name="sent_msgs">')
    (tmp_path / "daa_sil.xml").write_text(xml)
    out = dialect.generate(tmp_path / "daa_sil.py", tmp_path / "daa_sil.xml")
    assert out.read_bytes() != dialect.MODULE_PATH.read_bytes()
