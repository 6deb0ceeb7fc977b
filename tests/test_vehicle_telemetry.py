"""Sans-IO parts of the vehicle's MAVLink face: identity and modes, stream rates, telemetry builders,
connection strings. Hand-worked numbers; every probe is a state where the answer is not trivial."""

from __future__ import annotations

import math

import pytest

from daa_sil.errors import UsageError
from daa_sil.link.codec import mavlink as M
from daa_sil.sil.connstr import LISTEN, SEND, describe, parse_connection
from vehicle import identity as ident
from vehicle import telemetry as T
from vehicle.streams import StreamRates


# --- identity and modes -------------------------------------------------------------------------------
def test_authorities_map_to_arduplane_modes_by_name():
    assert [ident.mode_name(ident.mode_of(a)) for a in ("pilot", "daa", "waiting")] == ["GUIDED", "AVOID_ADSB", "CRUISE"]
    assert ident.mode_of("daa", agent_enabled=False) == ident.GUIDED  # the agent off never takes authority
    from daa_sil.agent.decision import AUTHORITY_NAMES

    # every authority the agent names has its mode and its wire code (a renamed one cannot fall back silently)
    assert set(ident.AUTHORITY_MODE) == set(AUTHORITY_NAMES) == set(T.AUTHORITY_CODE)
    from pymavlink import mavutil

    for num, name in ident.PLANE_MODES.items():  # the same numbering pymavlink / MAVProxy decode with
        assert mavutil.mode_mapping_apm[num] == name


def test_base_mode_as_arduplane():
    b = ident.base_mode(ident.GUIDED)
    assert b & M.MAV_MODE_FLAG_SAFETY_ARMED and b & M.MAV_MODE_FLAG_GUIDED_ENABLED and b & 1
    assert not ident.base_mode(ident.CRUISE) & M.MAV_MODE_FLAG_GUIDED_ENABLED
    hb = T.heartbeat("waiting")
    assert (hb.autopilot, hb.type, hb.custom_mode) == (M.MAV_AUTOPILOT_ARDUPILOTMEGA, M.MAV_TYPE_FIXED_WING, 7)


@pytest.mark.parametrize("base,custom,current,result", [
    (1, 15, 15, M.MAV_RESULT_ACCEPTED),
    (1, 15, 14, M.MAV_RESULT_ACCEPTED),  # the agent flies (AVOID_ADSB): the pilot's commands go to it all the same
    (1, 15, 7, M.MAV_RESULT_ACCEPTED),  # the agent waits (CRUISE); on main both were TEMPORARILY_REJECTED
    (1, 14, 15, M.MAV_RESULT_DENIED),
    (1, 7, 15, M.MAV_RESULT_DENIED),
    (1, 11, 15, M.MAV_RESULT_DENIED),
    (0, 15, 15, M.MAV_RESULT_DENIED),
])
def test_mode_requests(base, custom, current, result):
    r, reason = ident.mode_request(base, custom, current)
    assert r == result and 0 < len(reason) <= 50


# --- stream rates -----------------------------------------------------------------------------------
GPI, HUD, HOME = M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, M.MAVLINK_MSG_ID_VFR_HUD, M.MAVLINK_MSG_ID_HOME_POSITION


def _emissions(r: StreamRates, msg: int, t0: int, t1: int, also: "dict | None" = None) -> list:
    """Steps in [t0, t1) at which ``msg`` goes out (``also``: msg -> list, filled for other messages)."""
    out = []
    for t in range(t0, t1):
        due = r.due(float(t))
        out += [t] if msg in due else []
        for m, lst in (also or {}).items():
            lst += [t] if m in due else []
    return out


def test_defaults_every_step_home_once():
    r = StreamRates(1.0)
    assert _emissions(StreamRates(1.0), GPI, 0, 5) == [0, 1, 2, 3, 4]
    assert HOME in r.due(0.0) and HOME not in r.due(1.0)
    assert r.request_once(HOME) and HOME in r.due(2.0) and HOME not in r.due(3.0)
    assert not r.request_once(12345)


def test_interval_in_sim_time_and_refusals():
    r = StreamRates(1.0)
    r.due(0.0)
    assert r.set_interval(HUD, 2.5e6, 1.0)[0] == M.MAV_RESULT_ACCEPTED
    assert _emissions(r, HUD, 1, 10) == [1, 4, 7]  # due 1, 3.5 -> 4, 6.5 -> 7: at the first step at/after due
    # issue 20 §11: faster than the 1 s step is accepted (as ArduPilot SITL), sent once per step, said in a
    # STATUSTEXT (<= 50 characters), and GET_MESSAGE_INTERVAL reports the interval used: one step
    res, why = r.set_interval(HUD, 250_000, 10.0)
    assert res == M.MAV_RESULT_ACCEPTED and why == "VFR_HUD once per step (1 s)" and r.interval_us(HUD) == 1_000_000
    assert _emissions(r, HUD, 10, 14) == [10, 11, 12, 13]
    assert r.set_interval(HUD, 1e6, 14.0) == (M.MAV_RESULT_ACCEPTED, "")  # exactly one step: nothing to say
    long_name = M.MAVLINK_MSG_ID_POSITION_TARGET_GLOBAL_INT
    assert len(r.set_interval(long_name, 1, 14.0)[1]) <= 50 and r.interval_us(long_name) == 1_000_000
    assert r.set_interval(HUD, -1, 10.0)[0] == M.MAV_RESULT_ACCEPTED and r.interval_us(HUD) == -1
    assert _emissions(r, HUD, 10, 15) == []
    assert r.set_interval(HUD, 0, 15.0)[0] == M.MAV_RESULT_ACCEPTED and r.interval_us(HUD) == 1_000_000
    assert r.set_interval(M.MAVLINK_MSG_ID_HEARTBEAT, 5e6, 0.0)[0] == M.MAV_RESULT_DENIED
    assert r.set_interval(M.MAVLINK_MSG_ID_HEARTBEAT, -1, 0.0)[0] == M.MAV_RESULT_DENIED  # liveness needs it
    assert r.set_interval(M.MAVLINK_MSG_ID_HEARTBEAT, 2e5, 0.0)[0] == M.MAV_RESULT_ACCEPTED  # once per step anyway
    # MESSAGE_INTERVAL reports int32 microseconds: a longer interval is refused, never stored
    assert r.set_interval(HUD, 2**31, 0.0)[0] == M.MAV_RESULT_DENIED and r.interval_us(HUD) == 1_000_000
    assert r.set_interval(HUD, 2**31 - 1, 0.0)[0] == M.MAV_RESULT_ACCEPTED and r.interval_us(HUD) == 2**31 - 1
    assert r.set_interval(999, 1e6, 0.0)[0] == M.MAV_RESULT_UNSUPPORTED and r.interval_us(999) == 0
    assert r.set_interval(HUD, -5, 0.0)[0] == M.MAV_RESULT_DENIED


def test_request_data_stream_groups_and_clamp():
    r = StreamRates(1.0)
    r.due(0.0)
    assert r.request_data_stream(M.MAV_DATA_STREAM_POSITION, 0, True, 1.0) == ""
    hud: list = []
    assert _emissions(r, GPI, 1, 4, {HUD: hud}) == [] and hud == [1, 2, 3]
    note = r.request_data_stream(M.MAV_DATA_STREAM_ALL, 4, True, 4.0)
    assert "above the sim rate" in note and _emissions(r, GPI, 4, 7) == [4, 5, 6]  # 4 Hz -> once per step
    assert r.request_data_stream(M.MAV_DATA_STREAM_ALL, 4, True, 7.0) == ""  # said once
    r.request_data_stream(M.MAV_DATA_STREAM_EXTRA2, 0.25, True, 7.0)  # 0.25 Hz = every 4 s
    assert _emissions(r, HUD, 7, 16) == [7, 11, 15]
    assert r.request_data_stream(M.MAV_DATA_STREAM_RC_CHANNELS, 4, True, 0.0) == ""  # nothing we have


# --- telemetry builders ------------------------------------------------------------------------------
def test_attitude_is_the_coordinated_turn():
    w = math.radians(3.0)
    a = T.attitude(12.0, T.Kin(0, 0, 1000, 55.0, math.radians(90), 2.0, w))
    phi = math.atan(55.0 * w / 9.80665)
    assert abs(math.degrees(phi) - 16.365) < 1e-3 and abs(a.roll - phi) < 1e-6
    assert abs(a.pitch - math.atan2(2.0, 55.0)) < 1e-6 and abs(a.yaw - math.pi / 2) < 1e-6
    assert abs(a.yawspeed - w * math.cos(phi)) < 1e-7 and abs(a.pitchspeed - w * math.sin(phi)) < 1e-7
    left = T.attitude(12.0, T.Kin(0, 0, 1000, 55.0, 0.0, 0.0, -w))
    assert abs(left.roll + phi) < 1e-6 and T.attitude(0.0, T.Kin(0, 0, 0, 55.0, 0.0, 0.0, math.nan)).roll == 0.0


def test_position_target_reports_the_executed_velocity():
    own = T.Kin(0, 0, 1000, 55.0, 0.0, 0.0)
    m = T.position_target(3.0, 90.0, 60.0, -2.0, own)
    assert abs(m.vx) < 1e-9 and abs(m.vy - 60.0) < 1e-9 and m.vz == 2.0 and m.type_mask == 0x0DC7
    keep = T.position_target(3.0, math.nan, math.nan, math.nan, own)
    assert abs(keep.vx - 55.0) < 1e-9 and keep.vz == 0.0


def test_status_messages_say_what_is_simulated():
    s = T.sys_status(True)
    gps = M.MAV_SYS_STATUS_SENSOR_GPS
    assert s.onboard_control_sensors_health & gps and s.onboard_control_sensors_enabled & (1 << 29)
    assert not T.sys_status(False).onboard_control_sensors_enabled & (1 << 29)
    assert (s.voltage_battery, s.current_battery, s.battery_remaining) == (65535, -1, -1)
    assert T.software_version("0.1.0") == (1 << 16) | M.FIRMWARE_VERSION_TYPE_DEV
    av = T.autopilot_version()
    assert av.capabilities == ident.CAPABILITIES and not av.capabilities & M.MAV_PROTOCOL_CAPABILITY_FTP


# --- connection strings ------------------------------------------------------------------------------
@pytest.mark.parametrize("text,option,default,role,addr", [
    ("udpin:0.0.0.0:14550", "--out", SEND, LISTEN, ("0.0.0.0", 14550)),
    ("udpout:127.0.0.1:14550", "--out", SEND, SEND, ("127.0.0.1", 14550)),
    ("udp:127.0.0.1:14550", "--out", SEND, SEND, ("127.0.0.1", 14550)),
    ("udp:127.0.0.1:0", "--listen", LISTEN, LISTEN, ("127.0.0.1", 0)),
    ("udpin:127.0.0.1:14560", "--listen", LISTEN, LISTEN, ("127.0.0.1", 14560)),
    ("127.0.0.1:14601", "--vehicle", SEND, SEND, ("127.0.0.1", 14601)),
])
def test_connection_strings_as_mavproxy(text, option, default, role, addr):
    c = parse_connection(text, option, default)
    assert (c.role, c.addr) == (role, addr)
    assert describe(c).startswith("udpin:" if role == LISTEN else "udpout:")


@pytest.mark.parametrize("text,option,default,allow,needle", [
    ("udpout:127.0.0.1:5", "--listen", LISTEN, (LISTEN,), "use udp:, udpin:HOST:PORT"),
    ("udpin:127.0.0.1:5", "--tap", SEND, (SEND,), "use udp:, udpout:HOST:PORT"),
    ("tcp:127.0.0.1:5760", "--out", SEND, (LISTEN, SEND), "only UDP is supported (udp:HOST:PORT, udpin:HOST:PORT or udpout:HOST:PORT)"),
    ("udp:127.0.0.1:0", "--out", SEND, (LISTEN, SEND), "within [1, 65535]"),
    ("serial:/dev/ttyUSB0", "--out", SEND, (LISTEN, SEND), "only UDP is supported (udp:HOST:PORT, udpin:HOST:PORT or udpout:HOST:PORT)"),
])
def test_other_connection_strings_are_one_line_errors(text, option, default, allow, needle):
    with pytest.raises(UsageError) as ei:
        parse_connection(text, option, default, allow=allow)
    msg = str(ei.value)
    assert msg.startswith(option) and needle in msg and "\n" not in msg
