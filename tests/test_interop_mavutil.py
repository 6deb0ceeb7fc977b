"""A stock pymavlink ``mavutil`` ground station (common dialect) against a real ``daa-vehicle`` process.

Population: one realtime vehicle process (head-on scenario, 5x) talking straight to a mavutil
``udpin`` connection on an OS-chosen loopback port; each test exercises one service the way a
stock client sends it and checks the answer field by field, including the refusals.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import pytest

from interop_helpers import ROOT, free_ports, recv_until, start, stop, corrective_reading

SCENARIO = ROOT / "scenarios" / "head_on.yaml"


def long_scenario(tmp, duration_s: float = 600.0):
    """The head-on scenario lengthened so the vehicle outlives every test of a module."""
    import yaml

    from daa_sil.sil.scenario import load_scenario

    d = load_scenario(SCENARIO).to_dict()
    d["duration_s"] = duration_s
    path = tmp / "head_on_long.yaml"
    path.write_text(yaml.safe_dump(d, sort_keys=False))
    return path


@pytest.fixture(scope="module")
def link(tmp_path_factory):
    os.environ["MAVLINK20"] = "1"
    from pymavlink import mavutil

    tmp = tmp_path_factory.mktemp("mavutil")
    port, tap = free_ports(2)
    conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255, source_component=190,
                                      dialect="common")
    tapc = mavutil.mavlink_connection(f"udpin:127.0.0.1:{tap}", source_system=254, source_component=190,
                                      dialect="common")
    proc = start(["vehicle", long_scenario(tmp), *corrective_reading(tmp), "--out", f"udp:127.0.0.1:{port}", "--tap", f"udp:127.0.0.1:{tap}",
                  "--speed", "5", "--steplog", tmp / "steplog.parquet"], tmp / "vehicle.log")
    try:
        # the vehicle is on the link while it boots (MAV_STATE_BOOT): the tests start once it flies (ACTIVE)
        active = lambda m: m.get_type() == "HEARTBEAT" and m.system_status == 4  # noqa: E731
        assert recv_until(conn, active, 120.0), "no ACTIVE HEARTBEAT from the vehicle"
        recv_until(tapc, active, 10.0)
        yield conn, tapc, proc, tmp
    finally:
        stop(proc)
        conn.close()
        tapc.close()


def _ack(conn, command, timeout=5.0):
    got = recv_until(conn, lambda m: m.get_type() == "COMMAND_ACK" and m.command == command, timeout)
    acks = [m for m in got if m.get_type() == "COMMAND_ACK" and m.command == command]
    assert acks, f"no COMMAND_ACK for command {command}"
    return acks[-1], got


def test_identity_is_an_arduplane_in_guided(link):
    from pymavlink import mavutil

    conn, *_ = link
    hb = recv_until(conn, lambda m: m.get_type() == "HEARTBEAT", 5.0)[-1]
    assert (hb.type, hb.autopilot) == (mavutil.mavlink.MAV_TYPE_FIXED_WING, mavutil.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA)
    assert hb.custom_mode == 15 and conn.flightmode == "GUIDED"  # pymavlink's ArduPlane table
    assert hb.base_mode & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED and hb.system_status == 4  # armed, active
    conn.mav.command_long_send(1, 1, mavutil.mavlink.MAV_CMD_REQUEST_MESSAGE, 0, 148, 0, 0, 0, 0, 0, 0)
    _, got = _ack(conn, mavutil.mavlink.MAV_CMD_REQUEST_MESSAGE)
    av = [m for m in recv_until(conn, lambda m: m.get_type() == "AUTOPILOT_VERSION", 5.0) + got
          if m.get_type() == "AUTOPILOT_VERSION"][-1]
    cap = mavutil.mavlink
    assert av.capabilities & cap.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    assert av.capabilities & cap.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST
    assert not av.capabilities & (cap.MAV_PROTOCOL_CAPABILITY_FTP | cap.MAV_PROTOCOL_CAPABILITY_MISSION_INT
                                  | cap.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE)  # not served
    assert av.flight_sw_version >> 8 == 0x000100  # daa-sil 0.1.0


def test_mode_requests_are_answered_and_never_override_the_agent(link):
    from pymavlink import mavutil

    conn, tapc, proc, tmp = link
    m = mavutil.mavlink
    conn.mav.command_long_send(1, 1, m.MAV_CMD_DO_SET_MODE, 0, 1, 15, 0, 0, 0, 0, 0)  # GUIDED: the pilot's mode
    assert _ack(conn, m.MAV_CMD_DO_SET_MODE)[0].result == m.MAV_RESULT_ACCEPTED
    conn.mav.set_mode_send(1, 1, 14)  # the SET_MODE message, AVOID_ADSB: only the agent enters it
    ack, got = _ack(conn, m.MAVLINK_MSG_ID_SET_MODE)
    assert ack.result == m.MAV_RESULT_DENIED
    conn.mav.command_long_send(1, 1, m.MAV_CMD_DO_SET_MODE, 0, 1, 11, 0, 0, 0, 0, 0)  # RTL: not available
    assert _ack(conn, m.MAV_CMD_DO_SET_MODE)[0].result == m.MAV_RESULT_DENIED
    conn.mav.command_long_send(1, 1, m.MAV_CMD_DO_SET_MODE, 0, 0, 15, 0, 0, 0, 0, 0)  # no custom-mode flag
    assert _ack(conn, m.MAV_CMD_DO_SET_MODE)[0].result == m.MAV_RESULT_DENIED
    tapc.mav.command_long_send(1, 1, m.MAV_CMD_DO_SET_MODE, 0, 1, 15, 0, 0, 0, 0, 0)  # tap: read-only
    assert _ack(tapc, m.MAV_CMD_DO_SET_MODE)[0].result == m.MAV_RESULT_DENIED
    hb = recv_until(conn, lambda x: x.get_type() == "HEARTBEAT", 3.0)[-1]
    assert hb.custom_mode == 15
    conn.mav.param_request_read_send(1, 1, b"DAA_ENABLE", -1)
    v, _ = _param(conn, "DAA_ENABLE")
    assert v.param_value == 1.0  # no mode request switched the agent


def test_standard_telemetry_set_is_consistent(link):
    conn, *_ = link
    want = {"SYS_STATUS", "GPS_RAW_INT", "GLOBAL_POSITION_INT", "ATTITUDE", "VFR_HUD", "EXTENDED_SYS_STATE",
            "ADSB_VEHICLE", "POSITION_TARGET_GLOBAL_INT", "SYSTEM_TIME", "HEARTBEAT"}
    msgs = recv_until(conn, lambda m: False, 2.0)
    seen = {m.get_type(): m for m in msgs}
    assert want <= set(seen), want - set(seen)
    pos, gps, hud = seen["GLOBAL_POSITION_INT"], seen["GPS_RAW_INT"], seen["VFR_HUD"]
    assert gps.fix_type == 3 and abs(gps.lat - pos.lat) < 2000 and abs(gps.alt - pos.alt) < 1000
    assert abs(hud.groundspeed - math.hypot(pos.vx, pos.vy) / 100) < 0.05 and abs(hud.alt - pos.alt / 1000) < 1
    assert seen["EXTENDED_SYS_STATE"].landed_state == 2  # in air
    s = seen["SYS_STATUS"]
    assert s.onboard_control_sensors_health & 32 and s.onboard_control_sensors_enabled & (1 << 29)  # GPS, avoidance
    assert s.battery_remaining == -1  # no battery model: "unknown"


def test_home_position_on_request_and_get_home(link):
    from pymavlink import mavutil

    conn, *_ = link
    conn.mav.command_long_send(1, 1, mavutil.mavlink.MAV_CMD_GET_HOME_POSITION, 0, 0, 0, 0, 0, 0, 0, 0)
    ack, got = _ack(conn, mavutil.mavlink.MAV_CMD_GET_HOME_POSITION)
    assert ack.result == 0
    homes = [m for m in got + recv_until(conn, lambda m: m.get_type() == "HOME_POSITION", 3.0)
             if m.get_type() == "HOME_POSITION"]
    assert homes
    from daa_sil.sil.scenario import load_scenario

    sc = load_scenario(SCENARIO)
    h = homes[-1]
    assert abs(h.latitude / 1e7 - sc.origin.lat_deg) < 0.2 and abs(h.altitude / 1000 - (sc.origin.alt_m + 1000)) < 5


def test_message_interval_faster_than_the_sim_step_is_sent_once_per_step(link):
    """Issue 20 §11: like ArduPilot SITL, a faster SET_MESSAGE_INTERVAL is ACCEPTED (a GCS reports an error
    on DENIED), the message goes out once per step, a STATUSTEXT says so, GET reports the interval used."""
    from pymavlink import mavutil

    conn, *_ = link
    m = mavutil.mavlink
    conn.mav.command_long_send(1, 1, m.MAV_CMD_SET_MESSAGE_INTERVAL, 0, m.MAVLINK_MSG_ID_VFR_HUD, 250000, 0, 0, 0, 0, 0)
    ack, got = _ack(conn, m.MAV_CMD_SET_MESSAGE_INTERVAL)
    assert ack.result == m.MAV_RESULT_ACCEPTED
    texts = [x.text for x in got + recv_until(conn, lambda x: x.get_type() == "STATUSTEXT", 2.0)
             if x.get_type() == "STATUSTEXT"]
    assert "VFR_HUD once per step (1 s)" in texts, texts
    conn.mav.command_long_send(1, 1, m.MAV_CMD_GET_MESSAGE_INTERVAL, 0, m.MAVLINK_MSG_ID_VFR_HUD, 0, 0, 0, 0, 0, 0)
    iv = [x for x in recv_until(conn, lambda x: x.get_type() == "MESSAGE_INTERVAL", 3.0) if x.get_type() == "MESSAGE_INTERVAL"]
    assert iv and iv[-1].interval_us == 1_000_000
    msgs = recv_until(conn, lambda x: False, 3.0)
    n_pos = sum(x.get_type() == "GLOBAL_POSITION_INT" for x in msgs)  # once per step, in the step's datagram
    n_hud = sum(x.get_type() == "VFR_HUD" for x in msgs)
    assert n_pos >= 6 and abs(n_hud - n_pos) <= 1, (n_pos, n_hud)  # VFR_HUD in every step's datagram, no more
    # a 3 s interval is honoured in sim time: VFR_HUD every 3rd step, GLOBAL_POSITION_INT still every step
    conn.mav.command_long_send(1, 1, m.MAV_CMD_SET_MESSAGE_INTERVAL, 0, m.MAVLINK_MSG_ID_VFR_HUD, 3e6, 0, 0, 0, 0, 0)
    assert _ack(conn, m.MAV_CMD_SET_MESSAGE_INTERVAL)[0].result == m.MAV_RESULT_ACCEPTED
    recv_until(conn, lambda x: x.get_type() == "VFR_HUD", 3.0)
    msgs = recv_until(conn, lambda x: False, 3.0)
    pos = [x.time_boot_ms for x in msgs if x.get_type() == "GLOBAL_POSITION_INT"]
    times = sorted({x.time_boot_ms for x in msgs if x.get_type() == "SYSTEM_TIME"})
    n_hud = sum(x.get_type() == "VFR_HUD" for x in msgs)
    assert len(pos) >= 12 and 0 < n_hud <= len(pos) // 3 + 1, (len(pos), n_hud)
    assert times  # SYSTEM_TIME still streams
    conn.mav.command_long_send(1, 1, m.MAV_CMD_GET_MESSAGE_INTERVAL, 0, m.MAVLINK_MSG_ID_VFR_HUD, 0, 0, 0, 0, 0, 0)
    iv = [x for x in recv_until(conn, lambda x: x.get_type() == "MESSAGE_INTERVAL", 3.0) if x.get_type() == "MESSAGE_INTERVAL"]
    assert iv and iv[-1].interval_us == 3_000_000
    conn.mav.command_long_send(1, 1, m.MAV_CMD_SET_MESSAGE_INTERVAL, 0, m.MAVLINK_MSG_ID_VFR_HUD, 0, 0, 0, 0, 0, 0)
    assert _ack(conn, m.MAV_CMD_SET_MESSAGE_INTERVAL)[0].result == m.MAV_RESULT_ACCEPTED  # back to the default


def test_request_data_stream_stops_and_restarts_a_group(link):
    from pymavlink import mavutil

    conn, *_ = link
    m = mavutil.mavlink
    conn.mav.request_data_stream_send(1, 1, m.MAV_DATA_STREAM_EXTRA1, 0, 0)  # stop ATTITUDE
    recv_until(conn, lambda x: False, 1.0)
    quiet = recv_until(conn, lambda x: False, 2.0)
    assert not [x for x in quiet if x.get_type() == "ATTITUDE"]
    assert [x for x in quiet if x.get_type() == "GLOBAL_POSITION_INT"]
    conn.mav.request_data_stream_send(1, 1, m.MAV_DATA_STREAM_EXTRA1, 4, 1)  # 4 Hz: above the sim rate
    back = recv_until(conn, lambda x: x.get_type() == "ATTITUDE", 3.0)
    assert back and back[-1].get_type() == "ATTITUDE"
    texts = [x.text for x in back if x.get_type() == "STATUSTEXT"]
    assert any("above the sim rate" in t for t in texts), texts


def test_timesync_and_ping_are_answered(link):
    conn, *_ = link
    conn.mav.timesync_send(0, 123456789)
    ts = [x for x in recv_until(conn, lambda x: x.get_type() == "TIMESYNC", 3.0) if x.get_type() == "TIMESYNC"]
    assert ts and ts[-1].ts1 == 123456789 and ts[-1].tc1 > 0
    conn.mav.ping_send(42, 7, 0, 0)
    pg = [x for x in recv_until(conn, lambda x: x.get_type() == "PING", 3.0) if x.get_type() == "PING"]
    assert pg and (pg[-1].seq, pg[-1].time_usec, pg[-1].target_system, pg[-1].target_component) == (7, 42, 255, 190)


def test_arm_is_accepted_and_disarm_refused_while_airborne(link):
    from pymavlink import mavutil

    conn, *_ = link
    m = mavutil.mavlink
    conn.mav.command_long_send(1, 1, m.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
    assert _ack(conn, m.MAV_CMD_COMPONENT_ARM_DISARM)[0].result == m.MAV_RESULT_ACCEPTED
    conn.mav.command_long_send(1, 1, m.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 21196, 0, 0, 0, 0, 0)
    assert _ack(conn, m.MAV_CMD_COMPONENT_ARM_DISARM)[0].result == m.MAV_RESULT_FAILED
    conn.mav.command_long_send(1, 1, 31337, 0, 0, 0, 0, 0, 0, 0, 0)  # unknown command
    assert _ack(conn, 31337)[0].result == m.MAV_RESULT_UNSUPPORTED


def _param(conn, name, timeout=5.0):
    got = recv_until(conn, lambda x: x.get_type() == "PARAM_VALUE" and x.param_id == name, timeout)
    vals = [x for x in got if x.get_type() == "PARAM_VALUE" and x.param_id == name]
    return (vals[-1] if vals else None), got


def test_parameter_protocol_list_read_set_and_refusals(link):
    from pymavlink import mavutil

    conn, tapc, proc, tmp = link
    m = mavutil.mavlink
    conn.mav.param_request_list_send(1, 1)
    got = recv_until(conn, lambda x: x.get_type() == "PARAM_VALUE" and x.param_index == x.param_count - 1, 5.0)
    plist = {x.param_id: x for x in got if x.get_type() == "PARAM_VALUE"}
    assert {"DAA_ENABLE", "DAA_WT", "DAA_PROJL_S", "DAA_STALE_S", "DAA_LINK_TO", "DAA_WAIT_MODE", "DAA_PRESET"} <= set(plist)
    assert sorted(x.param_index for x in plist.values()) == list(range(plist["DAA_WT"].param_count))
    assert plist["DAA_WT"].param_value == 4.0 and plist["DAA_WT"].param_type == m.MAV_PARAM_TYPE_REAL32
    assert plist["DAA_ENABLE"].param_value == 1.0 and plist["DAA_ENABLE"].param_type == m.MAV_PARAM_TYPE_INT8
    assert plist["DAA_WAIT_MODE"].param_value == 2.0  # ID-1: the MDP map
    # read by index
    conn.mav.param_request_read_send(1, 1, b"", plist["DAA_LINK_TO"].param_index)
    v, _ = _param(conn, "DAA_LINK_TO")
    assert v is not None and v.param_value == 20.0
    # set: accepted from the next step, echoed
    conn.mav.param_set_send(1, 1, b"DAA_WT", 6.0, m.MAV_PARAM_TYPE_REAL32)
    v, _ = _param(conn, "DAA_WT")
    assert v is not None and v.param_value == 6.0
    # out of range and not-a-number: answered with the current value, and a STATUSTEXT saying why
    conn.mav.param_set_send(1, 1, b"DAA_WT", 500.0, m.MAV_PARAM_TYPE_REAL32)
    v, got = _param(conn, "DAA_WT")
    assert v is not None and v.param_value == 6.0
    texts = [x.text for x in got + recv_until(conn, lambda x: x.get_type() == "STATUSTEXT", 2.0)
             if x.get_type() == "STATUSTEXT"]
    assert any("out of range" in t for t in texts), texts
    conn.mav.param_set_send(1, 1, b"DAA_ENABLE", 0.5, m.MAV_PARAM_TYPE_INT8)
    v, _ = _param(conn, "DAA_ENABLE")
    assert v is not None and v.param_value == 1.0
    # read-only
    conn.mav.param_set_send(1, 1, b"DAA_PRESET", 1.0, m.MAV_PARAM_TYPE_INT8)
    v, _ = _param(conn, "DAA_PRESET")
    assert v is not None and v.param_value == 0.0  # do365 kept
    # unknown name: no PARAM_VALUE at all, a STATUSTEXT names it
    conn.mav.param_set_send(1, 1, b"NO_SUCH_PARAM", 1.0, m.MAV_PARAM_TYPE_REAL32)
    got = recv_until(conn, lambda x: x.get_type() == "STATUSTEXT" and "NO_SUCH_PARAM" in x.text, 3.0)
    assert not [x for x in got if x.get_type() == "PARAM_VALUE" and x.param_id == "NO_SUCH_PARAM"]
    assert got and "NO_SUCH_PARAM" in got[-1].text
    # the tap may read, but not write
    tapc.mav.param_request_read_send(1, 1, b"DAA_WT", -1)
    v, _ = _param(tapc, "DAA_WT")
    assert v is not None and v.param_value == 6.0
    tapc.mav.param_set_send(1, 1, b"DAA_WT", 9.0, m.MAV_PARAM_TYPE_REAL32)
    v, _ = _param(tapc, "DAA_WT")
    assert v is not None and v.param_value == 6.0
    conn.mav.param_request_read_send(1, 1, b"DAA_WT", -1)
    v, _ = _param(conn, "DAA_WT")
    assert v.param_value == 6.0


def quiet_scenario(tmp: Path) -> Path:
    """The lengthened head-on scenario with its intruder passing 5 km abeam: no alert, ever, so the
    vehicle flies exactly what its pilot commands (the agent never blends or takes over)."""
    import yaml

    d = yaml.safe_load(long_scenario(tmp).read_text())
    # the largest miss a scenario takes; DO-365 alerts need a HMD under 0.66 nmi (1.2 km)
    d["intruders"][0]["cpa"]["hmd_m"] = 5000.0
    path = tmp / "quiet.yaml"
    path.write_text(yaml.safe_dump(d, sort_keys=False))
    return path


def test_do_reposition_is_a_pilot_command(tmp_path):
    """DO_REPOSITION toward a point due east becomes the pilot's command "track 090 at 60 m/s".

    A vehicle of its own, with no conflict: in the shared head-on link the command arrived while the
    agent held authority or blended, so the executed setpoint was (rightly) not the pilot's."""
    os.environ["MAVLINK20"] = "1"
    from pymavlink import mavutil

    from daa_sil.geometry.frames import enu_to_geodetic
    from daa_sil.sil.scenario import load_scenario
    from daa_sil.steplog import read_steplog

    m = mavutil.mavlink
    sc = load_scenario(SCENARIO)
    scenario = quiet_scenario(tmp_path)
    (port,) = free_ports(1)
    conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255, source_component=190,
                                      dialect="common")
    proc = None
    try:
        proc = start(["vehicle", scenario, *corrective_reading(tmp_path), "--out", f"udp:127.0.0.1:{port}", "--speed", "5",
                      "--steplog", tmp_path / "steplog.parquet"], tmp_path / "vehicle.log")
        assert recv_until(conn, lambda x: x.get_type() == "HEARTBEAT", 30.0), (tmp_path / "vehicle.log").read_text()
        pos = recv_until(conn, lambda x: x.get_type() == "LOCAL_POSITION_NED", 3.0)[-1]
        # a point 5 km due east of the aircraft: the pilot command is "track 090"
        lat, lon, _ = enu_to_geodetic(pos.y + 5000.0, pos.x, 1000.0, sc.origin.lat_deg, sc.origin.lon_deg,
                                      sc.origin.alt_m)
        conn.mav.command_int_send(1, 1, m.MAV_FRAME_GLOBAL, m.MAV_CMD_DO_REPOSITION, 0, 0, 60.0, 0, 0, math.nan,
                                  int(float(lat) * 1e7), int(float(lon) * 1e7), 1000.0)
        assert _ack(conn, m.MAV_CMD_DO_REPOSITION)[0].result == m.MAV_RESULT_ACCEPTED
        tg = recv_until(conn, lambda x: x.get_type() == "POSITION_TARGET_GLOBAL_INT" and x.vy > 50, 5.0)[-1]
        assert tg.get_type() == "POSITION_TARGET_GLOBAL_INT"
        assert abs(tg.vx) < 1.0 and abs(math.hypot(tg.vx, tg.vy) - 60) < 0.01, (tg.vx, tg.vy)
        conn.mav.command_int_send(1, 1, m.MAV_FRAME_GLOBAL, m.MAV_CMD_DO_REPOSITION, 0, 0, 60.0, 0, 0, 0,
                                  int(95e7), 0, 1000.0)  # latitude 95 deg: invalid
        assert _ack(conn, m.MAV_CMD_DO_REPOSITION)[0].result == m.MAV_RESULT_DENIED
    finally:
        if proc is not None:
            stop(proc)
        conn.close()
    log = read_steplog(tmp_path / "steplog.parquet")
    col = {c: log.column(c).to_pylist() for c in ("alert_level", "authority", "pilot_trk_deg", "pilot_gs",
                                                    "cmd_trk_deg", "cmd_gs")}
    assert all(max(a) == 0 for a in col["alert_level"]) and set(col["authority"]) == {"pilot"}
    taken = [i for i, g in enumerate(col["pilot_gs"]) if g == 60.0]
    assert taken and taken == list(range(taken[0], len(col["pilot_gs"])))  # held from the step it arrived on
    assert all(abs(col["pilot_trk_deg"][i] - 90.0) < 1.0 and col["cmd_trk_deg"][i] == col["pilot_trk_deg"][i]
               and col["cmd_gs"][i] == 60.0 for i in taken)


def test_guided_is_accepted_while_the_agent_holds_authority(link):
    """Later in the encounter the agent takes authority (AVOID_ADSB / CRUISE): GUIDED is still ACCEPTED (the
    pilot's commands go to the agent, which judges them), and the heartbeat keeps showing who flies."""
    from pymavlink import mavutil

    conn, *_ = link
    m = mavutil.mavlink
    got = recv_until(conn, lambda x: x.get_type() == "HEARTBEAT" and x.custom_mode in (7, 14), 60.0)
    assert got and got[-1].get_type() == "HEARTBEAT" and got[-1].custom_mode in (7, 14), "the agent never took over"
    assert conn.flightmode in ("CRUISE", "AVOID_ADSB")
    conn.mav.command_long_send(1, 1, m.MAV_CMD_DO_SET_MODE, 0, 1, 15, 0, 0, 0, 0, 0)
    ack, around = _ack(conn, m.MAV_CMD_DO_SET_MODE)
    assert ack.result == m.MAV_RESULT_ACCEPTED  # on main: TEMPORARILY_REJECTED ("GUIDED refused: DAA agent flies")
    after = recv_until(conn, lambda x: x.get_type() == "HEARTBEAT", 3.0)
    assert after[-1].custom_mode in (7, 14), "a mode request does not take authority from the agent"


def test_settings_are_in_the_step_log(link):
    """Run last in this module: stops the vehicle and reads the settings it logged."""
    import json

    from daa_sil.steplog import steplog_metadata

    conn, tapc, proc, tmp = link
    assert stop(proc) == 130
    ev = json.loads(steplog_metadata(tmp / "steplog.parquet")["settings"])
    wt = [e for e in ev if e["name"] == "DAA_WT"]
    assert [(e["status"], e["link"]) for e in wt] == [("accepted", "gcs"), ("out_of_range", "gcs"),
                                                      ("denied_readonly", "tap")]
    assert wt[0]["old"] == 4.0 and wt[0]["new"] == 6.0 and wt[0]["t_sent"] is None  # mavutil stamps no send time
    assert wt[0]["t_applied"] >= wt[0]["t_received"] - 1e-9 and wt[0]["t_applied"] == round(wt[0]["t_applied"])
    modes = [(e["name"], e["status"]) for e in ev if e["kind"] == "mode"]
    assert modes[:5] == [("GUIDED", "accepted"), ("AVOID_ADSB", "denied"), ("RTL", "denied"), ("GUIDED", "denied"),
                         ("GUIDED", "denied_readonly")]
    assert modes[5][1] == "accepted"


def _hello(conn, tries: int = 50) -> list:
    """Say hello (HEARTBEAT) from ``conn`` until the vehicle's HEARTBEAT comes back; the messages received."""
    got = []
    for _ in range(tries):
        conn.mav.heartbeat_send(6, 8, 0, 0, 4)
        got = recv_until(conn, lambda m: m.get_type() == "HEARTBEAT", 0.2)
        if got and got[-1].get_type() == "HEARTBEAT":
            return got
    return got


def test_vehicle_out_udpin_answers_every_gcs_and_a_restarted_one(tmp_path):
    """``daa-vehicle --out udpin:`` as SITL: a mavutil ``udpout:`` client attaches; it is "restarted" (closed,
    a new one from a new port), and the new one is answered from its first heartbeat while a second GCS
    keeps its own stream. On main the vehicle answered only the first sender and dropped the rest ("the
    vehicle answers only the first GCS that sent"): the restarted GCS got nothing."""
    from pymavlink import mavutil

    (port,) = free_ports(1)
    proc = start(["vehicle", long_scenario(tmp_path), *corrective_reading(tmp_path), "--out", f"udpin:127.0.0.1:{port}", "--speed", "10",
                  "--steplog", tmp_path / "steplog.parquet"], tmp_path / "vehicle.log")
    conns = []

    def gcs(sysid: int):
        c = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=sysid, source_component=190,
                                       dialect="common")
        conns.append(c)
        return c

    try:
        from interop_helpers import wait_for_text

        ready = wait_for_text(tmp_path / "vehicle.log", "READY", 60.0, proc)
        assert f"listen=udp:127.0.0.1:{port} out=udpin:127.0.0.1:{port}" in ready
        first = gcs(255)
        got = _hello(first)
        assert got and got[-1].get_type() == "HEARTBEAT" and got[-1].autopilot == 3
        other = gcs(200)  # a second ground station at the same time
        assert _hello(other)[-1].get_type() == "HEARTBEAT"
        first.close()  # MAVProxy is restarted: its new socket has a new port
        restarted = gcs(255)
        got = _hello(restarted, tries=10)
        assert got and got[-1].get_type() == "HEARTBEAT", "the restarted GCS is not answered"
        restarted.mav.param_request_read_send(1, 1, b"DAA_WT", -1)
        v, _ = _param(restarted, "DAA_WT")
        assert v is not None and v.param_value == 4.0
        assert recv_until(other, lambda m: m.get_type() == "GLOBAL_POSITION_INT", 3.0)  # the other still streams
    finally:
        stop(proc)
        for c in conns:
            c.close()
    import json

    from daa_sil.steplog import steplog_metadata

    meta = steplog_metadata(tmp_path / "steplog.parquet")
    assert json.loads(meta["link"])["rejected_peer"] == 0
    assert "dropping datagrams" not in (tmp_path / "vehicle.log").read_text()


@pytest.mark.parametrize("args,needle", [
    (["--out", "udpin:127.0.0.1:14550", "--listen", "udp:127.0.0.1:0"], "already listens"),
    (["--listen", "udpout:127.0.0.1:5"], "--listen"),
    (["--tap", "udpin:127.0.0.1:5"], "--tap"),
    (["--out", "tcp:127.0.0.1:5760"], "the vehicle serves TCP clients instead: tcpin:HOST:PORT"),
    (["--tap", "tcpin:127.0.0.1:5760"], "is a TCP server; --tap takes UDP only"),
    (["--tap-writable"], "--tap-writable needs --tap"),
])
def test_vehicle_connection_string_errors_are_one_line(args, needle):
    import subprocess
    import sys

    cp = subprocess.run([sys.executable, "-m", "vehicle", str(SCENARIO), *args], capture_output=True, text=True,
                        timeout=60, cwd=ROOT)
    assert cp.returncode == 2 and cp.stderr.count("\n") == 1 and needle in cp.stderr, cp.stderr


def test_vehicle_out_tcpin_serves_reconnects_and_clients_with_their_own_rates(tmp_path):
    """``daa-vehicle --out tcpin:`` as SITL's 5760, with pymavlink's ``tcp:`` client: two clients at once, one
    stopping its VFR_HUD stops it for itself only; one disconnects and connects again and is served at once.
    On main ``tcpin:`` was refused ("only UDP is supported")."""
    import re

    from pymavlink import mavutil

    proc = start(["vehicle", long_scenario(tmp_path), "--out", "tcpin:127.0.0.1:0", "--speed", "10"],
                 tmp_path / "vehicle.log")
    conns = []

    def client():
        c = mavutil.mavlink_connection(f"tcp:127.0.0.1:{port}", source_system=255, source_component=190,
                                       dialect="common")
        conns.append(c)
        return c

    try:
        from interop_helpers import wait_for_text

        ready = wait_for_text(tmp_path / "vehicle.log", "READY", 60.0, proc)
        port = int(re.search(r"out=tcpin:127\.0\.0\.1:(\d+)", ready).group(1))
        a, b = client(), client()
        for c in (a, b):  # a TCP client is served from its connection on: no hello needed
            got = recv_until(c, lambda m: m.get_type() == "HEARTBEAT", 10.0)
            assert got and got[-1].get_type() == "HEARTBEAT" and got[-1].autopilot == 3
        b.mav.command_long_send(1, 1, mavutil.mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                mavutil.mavlink.MAVLINK_MSG_ID_VFR_HUD, -1, 0, 0, 0, 0, 0)
        ack, _ = _ack(b, mavutil.mavlink.MAV_CMD_SET_MESSAGE_INTERVAL)
        assert ack.result == mavutil.mavlink.MAV_RESULT_ACCEPTED
        recv_until(b, lambda m: False, 0.3)  # the step that was under way
        got_a = recv_until(a, lambda m: False, 1.0)
        got_b = recv_until(b, lambda m: False, 1.0)
        assert [m for m in got_a if m.get_type() == "VFR_HUD"] and not [m for m in got_b if m.get_type() == "VFR_HUD"]
        assert [m for m in got_b if m.get_type() == "GLOBAL_POSITION_INT"]
        a.close()
        again = client()  # reconnects (a new connection, from a new port)
        got = recv_until(again, lambda m: m.get_type() == "HEARTBEAT", 10.0)
        assert got and got[-1].get_type() == "HEARTBEAT"
        again.mav.param_request_read_send(1, 1, b"DAA_WT", -1)
        v, _ = _param(again, "DAA_WT")
        assert v is not None and v.param_value == 4.0
    finally:
        code = stop(proc)
        for c in conns:
            c.close()
    assert code == 130, (tmp_path / "vehicle.log").read_text()[-2000:]
