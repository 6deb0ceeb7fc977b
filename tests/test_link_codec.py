"""MavCodec: round trips, hostile input, signing (including the forged-timestamp lockout)."""

from __future__ import annotations

import hashlib
import math
import os
import stat
import struct
from pathlib import Path

import pytest

from daa_sil.errors import FileFormatError, OutputError, UsageError
from daa_sil.link.codec import CONTROL_LINK_ID, STALE_LIMIT, MavCodec, mavlink as d
from daa_sil.link.keys import generate_key_file, key_from_passphrase, load_key

KEY = hashlib.sha256(b"daa-sil test").digest()
NAN = float("nan")


def _messages():
    return [
        d.MAVLink_daa_bands_message(12000, d.DAA_SIL_BAND_DIMENSION_TRACK, 2, 0, 1,
                                    [10.0, 200.5] + [0.0] * 14, [45.0, 260.0] + [0.0] * 14,
                                    [d.DAA_SIL_BAND_REGION_NEAR, d.DAA_SIL_BAND_REGION_FAR] + [0] * 14),
        d.MAVLink_allocation_decision_message(13000, d.DAA_SIL_AUTHORITY_WAITING, d.DAA_SIL_DECISION_BLEND,
                                              d.DAA_SIL_RULE_AXIS_DIR, 7.5, 1, -2.25, 12.0, d.DAA_SIL_AXIS_HORIZONTAL,
                                              d.DAA_SIL_DIRECTION_LEFT, d.DAA_SIL_AXIS_VERTICAL,
                                              d.DAA_SIL_DIRECTION_UP, 270.0, 5.0, NAN, 42, 6.5),
        d.MAVLink_sim_tick_message(17, 17000),
        d.MAVLink_sim_tick_ack_message(17, 17000, 3),
        d.MAVLink_pilot_maneuver_message(14000, 9, 1, 1, 123.5, NAN, 55.0),
        d.MAVLink_heartbeat_message(d.MAV_TYPE_FIXED_WING, d.MAV_AUTOPILOT_GENERIC, 217, 1, d.MAV_STATE_ACTIVE, 3),
        d.MAVLink_system_time_message(1_700_000_000_000_000, 15000),
        d.MAVLink_global_position_int_message(15000, 473977420, 85455940, 1_000_000, 500_000, 5500, -120, 0, 9000),
        d.MAVLink_attitude_message(15000, 0.1, -0.05, 1.5, 0.0, 0.0, 0.01),
        d.MAVLink_adsb_vehicle_message(0xABCDEF, 473987420, 85465940, 1, 1_050_000, 27000, 10000, -250, b"INTR1",
                                       14, 1, 223, 1200),
        d.MAVLink_command_long_message(1, 1, d.MAV_CMD_DO_SET_MODE, 0, 1, 4, 0, 0, 0, 0, 0),
        d.MAVLink_command_ack_message(d.MAV_CMD_DO_SET_MODE, d.MAV_RESULT_ACCEPTED, 0, 0, 255, 190),
        d.MAVLink_statustext_message(d.MAV_SEVERITY_WARNING, b"authority -> onboard DAA", 0, 0),
        d.MAVLink_set_position_target_global_int_message(15000, 1, 1, d.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 0x09C7,
                                                         0, 0, 0.0, 20.0, 5.0, -1.0, 0, 0, 0, 0.25, 0),
    ]


def _f32(x):
    return struct.unpack("<f", struct.pack("<f", x))[0]


def _same(a, b):
    """Field-by-field equality after the wire's float32 rounding (NaN == NaN)."""
    for f in a.get_fieldnames():
        x, y = getattr(a, f), getattr(b, f)
        if isinstance(x, float) and math.isnan(x):
            assert math.isnan(y), f
        elif isinstance(x, float):
            assert _f32(x) == y, f
        elif isinstance(x, list):
            assert [_f32(v) if isinstance(v, float) else v for v in x] == list(y), f
        else:
            assert x == y or (isinstance(x, bytes) and x.decode() == y), f


@pytest.mark.parametrize("key", [None, KEY], ids=["unsigned", "signed"])
def test_round_trip_every_message(key):
    tx, rx = MavCodec(1, 1, key=key), MavCodec(255, 190, key=key)
    msgs = _messages()
    for i, m in enumerate(msgs):
        buf = tx.encode(m)
        (got,) = rx.decode(buf)
        assert got.get_type() == m.get_type()
        assert got.get_seq() == i and got.get_srcSystem() == 1 and got.get_srcComponent() == 1
        assert got.get_signed() == (key is not None)
        _same(m, got)
    assert rx.counters.messages_in == len(msgs) and rx.counters.dropped == 0
    # several messages coalesced in one datagram
    many = rx.decode(tx.encode_many(msgs[:4]))
    assert [m.get_type() for m in many] == ["DAA_BANDS", "ALLOCATION_DECISION", "SIM_TICK", "SIM_TICK_ACK"]


def test_sequence_wraps():
    tx, rx = MavCodec(1, 1), MavCodec(2, 1)
    seqs = [rx.decode(tx.encode(d.MAVLink_sim_tick_message(i, i)))[0].get_seq() for i in range(300)]
    assert seqs[:3] == [0, 1, 2] and seqs[255] == 255 and seqs[256] == 0


def test_hostile_datagrams_are_counted_and_never_wedge_the_parser():
    tx, rx = MavCodec(1, 1), MavCodec(2, 1)
    good = tx.encode(d.MAVLink_sim_tick_message(1, 1000))
    bad_crc = bytearray(tx.encode(d.MAVLink_sim_tick_message(2, 2000)))
    bad_crc[-1] ^= 0xFF
    assert rx.decode(bytes(bad_crc)) == [] and rx.counters.bad_crc == 1
    assert rx.decode(good[:7]) == [] and rx.counters.truncated == 1  # truncated...
    assert [m.tick for m in rx.decode(good)] == [1]  # ...does not corrupt the next datagram
    got = rx.decode(b"\x00garbage" + good)
    assert [m.tick for m in got] == [1] and rx.counters.bad_prefix == 1
    unknown = bytearray(good)
    unknown[7:10] = (60000).to_bytes(3, "little")  # id no dialect knows
    assert rx.decode(bytes(unknown)) == [] and rx.counters.unknown == 1
    bad_flags = bytearray(good)
    bad_flags[2] = 0x80
    assert rx.decode(bytes(bad_flags)) == [] and rx.counters.malformed == 1
    for junk in (b"", b"\xfd", b"\xfe\xff", bytes(range(256)) * 3, b"\xfd" * 300, os.urandom(1000)):
        rx.decode(junk)
    assert [m.tick for m in rx.decode(good)] == [1]


def test_signing_rejects_unsigned_wrong_key_replay_and_stale():
    veh = MavCodec(1, 1, key=KEY)
    hb = d.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3)
    unsigned = MavCodec(255, 190).encode(hb)
    assert veh.decode(unsigned) == [] and veh.counters.unsigned == 1
    wrong = MavCodec(255, 190, key=hashlib.sha256(b"other").digest()).encode(hb)
    assert veh.decode(wrong) == [] and veh.counters.bad_signature == 1
    gcs = MavCodec(255, 190, key=KEY, link_id=7)
    pkt = gcs.encode(hb)
    (m,) = veh.decode(pkt)
    assert m.get_signed() and m.get_link_id() == 7
    assert veh.decode(pkt) == [] and veh.counters.replayed == 1
    ts = veh.mav.signing.timestamp
    old = MavCodec(255, 191, key=KEY, initial_timestamp=ts - STALE_LIMIT - 100_000)  # 61 s behind
    old.mav.signing.sign_outgoing = True
    old_pkt = old.mav.heartbeat_encode(6, 8, 0, 0, 4).pack(old.mav)  # bypass the wall-clock bump
    assert veh.decode(old_pkt) == [] and veh.counters.stale == 1
    recent = MavCodec(255, 192, key=KEY, initial_timestamp=ts - STALE_LIMIT + 100_000)  # 59 s behind
    assert len(veh.decode(recent.mav.heartbeat_encode(6, 8, 0, 0, 4).pack(recent.mav))) == 1
    allow_hb = MavCodec(1, 1, key=KEY, allow_unsigned={0})
    assert len(allow_hb.decode(unsigned)) == 1 and allow_hb.counters.unsigned_accepted == 1
    # a bad signature is not rescued by allow_unsigned
    assert allow_hb.decode(wrong) == [] and allow_hb.counters.bad_signature == 1


def test_forged_future_timestamp_does_not_lock_out_the_real_stream():
    veh = MavCodec(1, 1, key=KEY)
    gcs = MavCodec(255, 190, key=KEY)
    assert len(veh.decode(gcs.encode(d.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3)))) == 1
    forger = MavCodec(255, 190, key=hashlib.sha256(b"attacker").digest(),
                      initial_timestamp=veh.mav.signing.timestamp + 100_000 * 86400)  # +1 day, same stream
    forger.mav.signing.sign_outgoing = True
    forged = forger.mav.heartbeat_encode(6, 8, 0, 0, 4).pack(forger.mav)
    assert veh.decode(forged) == [] and veh.counters.bad_signature == 1
    for i in range(5):
        assert len(veh.decode(gcs.encode(d.MAVLink_sim_tick_ack_message(i, i, 0)))) == 1


def test_pymavlink_stock_check_signature_is_poisoned():
    """The flaw SecureMAVLink fixes, shown on the stock generated class (fails if pymavlink fixes it)."""
    stock = d.MAVLink(None, 1, 1)
    stock.robust_parsing = True
    stock.signing.secret_key = KEY
    stock.signing.timestamp = MavCodec(1, 1, key=KEY).mav.signing.timestamp
    gcs = MavCodec(255, 190, key=KEY)
    forger = MavCodec(255, 190, key=hashlib.sha256(b"attacker").digest(),
                      initial_timestamp=stock.signing.timestamp + 100_000 * 86400)
    forger.mav.signing.sign_outgoing = True
    stock.parse_buffer(forger.mav.heartbeat_encode(6, 8, 0, 0, 4).pack(forger.mav))
    got = stock.parse_buffer(gcs.encode(d.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3)))
    assert got[0].get_type() == "BAD_DATA"


def test_control_link_id_is_a_separate_stream():
    gcs = MavCodec(255, 190, key=KEY)
    veh = MavCodec(1, 1, key=KEY)
    data = gcs.encode(d.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3))
    ack = gcs.encode(d.MAVLink_sim_tick_ack_message(1, 1000, 1), link_id=CONTROL_LINK_ID)
    assert veh.decode(ack)[0].get_link_id() == CONTROL_LINK_ID
    assert len(veh.decode(data)) == 1  # older data after newer control: still accepted
    assert gcs.mav.signing.link_id == 0


def test_key_files(tmp_path):
    p = tmp_path / "link.key"
    key = generate_key_file(p)
    assert len(key) == 32 and load_key(p) == key
    assert stat.S_IMODE(p.stat().st_mode) == 0o600
    with pytest.raises(OutputError, match="refusing to overwrite"):
        generate_key_file(p)
    pp = tmp_path / "pass.txt"
    pp.write_text("correct horse battery staple\n")
    assert load_key(pp) == hashlib.sha256(b"correct horse battery staple").digest()
    assert key_from_passphrase("x") == hashlib.sha256(b"x").digest()
    (tmp_path / "empty").write_text("  \n")
    with pytest.raises(FileFormatError, match="empty"):
        load_key(tmp_path / "empty")
    with pytest.raises(FileFormatError, match="cannot read"):
        load_key(tmp_path / "nope")
    with pytest.raises(UsageError, match="32 bytes"):
        MavCodec(1, 1, key=b"short")


def test_key_file_rules_permissions_short_passphrases_and_a_trailing_newline(tmp_path):
    """Issue 20 §7. A raw 32-byte key with a line break (``echo``, an editor) was taken silently as a
    passphrase (or refused as not UTF-8); a passphrase of 1 character was accepted; a key file anyone
    may read was used without a word. Now: binary + line break = the raw key (the break ignored), 32
    printable characters + line break = a passphrase, and a warning says which; passphrases need 8
    characters; a group/other-readable file is used with a warning naming ``chmod 600``."""
    import subprocess
    import sys

    raw = bytes(range(200, 232))  # 32 bytes, not UTF-8
    assert len(raw) == 32
    notes: list = []
    for ending in (b"\n", b"\r\n"):
        p = tmp_path / f"raw{len(ending)}.key"
        p.write_bytes(raw + ending)
        p.chmod(0o600)
        notes.clear()
        assert load_key(p, warn=notes.append) == raw
        assert len(notes) == 1 and "raw bytes and a line break" in notes[0] and "ignored" in notes[0]
    text = "0123456789abcdef0123456789abcdef"  # 32 printable characters: typed, so a passphrase
    p = tmp_path / "text.key"
    p.write_text(text + "\n")
    p.chmod(0o600)
    notes.clear()
    assert load_key(p, warn=notes.append) == hashlib.sha256(text.encode()).digest()
    assert len(notes) == 1 and "read as a passphrase" in notes[0]
    p.write_text(text)  # exactly 32 bytes: the raw key, as documented
    assert load_key(p) == text.encode()
    for short in ("x", "seven77", "  abc  \n"):
        s = tmp_path / "short.key"
        s.write_text(short)
        s.chmod(0o600)
        with pytest.raises(FileFormatError, match="at least 8"):
            load_key(s)
    ok = tmp_path / "eight.key"
    ok.write_text("eight888\n")
    ok.chmod(0o600)
    notes.clear()
    assert load_key(ok, warn=notes.append) == hashlib.sha256(b"eight888").digest() and notes == []
    wide = tmp_path / "wide.key"
    generate_key_file(wide)
    wide.chmod(0o644)
    notes.clear()
    assert len(load_key(wide, warn=notes.append)) == 32
    assert len(notes) == 1 and "readable by group or others (mode 0644)" in notes[0] and "chmod 600" in notes[0]
    # at the command line: the warning is one line on stderr; a short passphrase is one error line, exit 2
    s = tmp_path / "short.key"
    cp = subprocess.run([sys.executable, "-m", "vehicle", "scenarios/head_on.yaml", "--key", str(s)],
                        capture_output=True, text=True, timeout=120, cwd=Path(__file__).resolve().parents[1])
    assert cp.returncode == 2 and cp.stderr.strip().count("\n") == 0, cp.stderr
    assert cp.stderr.startswith("daa-vehicle: error: signing key file") and "at least 8" in cp.stderr
    cp = subprocess.run([sys.executable, "-m", "daa_sil.cli", "run", "scenarios/head_on.yaml", "--key", str(wide),
                         "--out", str(tmp_path / "run"), "--tap", "tcp:127.0.0.1:1"],
                        capture_output=True, text=True, timeout=120, cwd=Path(__file__).resolve().parents[1])
    lines = cp.stderr.strip().splitlines()
    assert cp.returncode == 2 and len(lines) == 2, cp.stderr  # the key warning, then the --tap error
    assert lines[0].startswith("daa-sil: warning: signing key file") and "chmod 600" in lines[0]


@pytest.mark.parametrize("key", [None, KEY], ids=["unsigned", "signed"])
def test_unread_packets_pass_the_same_checks_as_decoded_ones(key):
    """A codec with ``read_ids`` against one without, fed the same genuine, replayed, stale, forged and
    fuzzed datagrams: it returns exactly the read messages the full decode returns, counts every other
    good packet as ``unread`` and every bad one under the same reason, and ends every datagram with the
    same signing state (stream time stamps, own time stamp, unsigned packets accepted)."""
    from daa_sil.link.fuzz import CRAFTED, Fuzzer

    msgs = _messages()
    read = {m.get_msgId() for m in msgs[::2]}  # half the types
    senders = [MavCodec(255, 190, key=key), MavCodec(255, 191, key=key, link_id=3)]
    genuine = [senders[i % 2].encode_many(msgs[i % len(msgs):] [:3]) for i in range(40)]
    stream = list(genuine)
    stream += genuine[:10]  # replays (with a key) of packets already seen
    if key is not None:
        ts = senders[0].mav.signing.timestamp
        for offset in (-STALE_LIMIT - 100_000, STALE_LIMIT):  # a stale new stream, then a future one
            other = MavCodec(255, 192 + (offset > 0), key=key, initial_timestamp=ts + offset)
            other.mav.signing.sign_outgoing = True
            stream.append(b"".join(m.pack(other.mav) for m in msgs[:4]))
        stream.append(MavCodec(255, 190, key=hashlib.sha256(b"forger").digest()).encode_many(msgs[:6]))
        stream.append(MavCodec(255, 190).encode_many(msgs[:6]))  # unsigned
    fuzz = Fuzzer(genuine, seed=5, crafted=CRAFTED["gcs"])
    stream += [fuzz.next()[1] for _ in range(600)]
    now = senders[0].mav.signing.timestamp  # (one starting time stamp for both receivers)
    full = MavCodec(1, 1, key=key, allow_unsigned={0}, initial_timestamp=now)
    part = MavCodec(1, 1, key=key, allow_unsigned={0}, read_ids=read, initial_timestamp=now)
    for data in stream:
        want = [m.get_msgbuf() for m in full.decode(data) if m.get_msgId() in read]
        assert [m.get_msgbuf() for m in part.decode(data)] == want
        a, b = full.counters.as_dict(), part.counters.as_dict()
        assert b["messages_in"] + b["unread"] == a["messages_in"] and a["unread"] == 0
        assert {k: v for k, v in a.items() if k not in ("messages_in", "signed_in", "unread")} == \
            {k: v for k, v in b.items() if k not in ("messages_in", "signed_in", "unread")}
        sa, sb = full.mav.signing, part.mav.signing
        assert (sa.stream_timestamps, sa.timestamp, full.mav.n_unsigned_accepted) == \
            (sb.stream_timestamps, sb.timestamp, part.mav.n_unsigned_accepted)
    c = part.counters
    assert c.unread > 50 and c.messages_in > 50 and c.bad_crc > 50 and c.unknown > 0
    if key is not None:
        assert c.replayed >= 10 and c.stale >= 4 and c.bad_signature >= 6 and c.unsigned >= 5
        assert c.unsigned_accepted >= 1 and 0 < c.signed_in <= c.messages_in  # (the accepted HEARTBEAT is unread)
    # decoded without commit (a stranger's datagram), nothing is left unread: the whole datagram is returned
    assert len(MavCodec(1, 1, read_ids=read).decode(genuine[0], commit=False)) == 3
