"""MAVSDK (the native ``mavsdk`` wheel, v4: libcmavsdk inside) as a ground station against a real vehicle.

Population: one realtime vehicle process (head-on scenario lengthened, 2x) streaming straight to
MAVSDK's ``udpin://`` connection on an OS-chosen loopback port. MAVSDK was written by others and
decodes our HEARTBEAT, SYS_STATUS, HOME_POSITION, GLOBAL_POSITION_INT, ATTITUDE and parameters
by its own rules, so what it reports is an external check of each.

Flight mode: MAVSDK 4.1 decodes ArduPlane's GUIDED / AVOID_ADSB / CRUISE into its core modes but
its telemetry enum has no name for them, so ``flight_mode()`` reports UNKNOWN for all three (it
names only MANUAL, STABILIZED, ACRO, RTL, LOITER-as-HOLD, AUTO-as-MISSION and TAKEOFF of
ArduPlane's). What MAVSDK does use is the mode number: its ``goto_location`` first asks for its
Offboard mode, which it translates to ArduPlane GUIDED (15) and which the vehicle accepts.
"""

from __future__ import annotations

import asyncio
import json
import math
import os

import pytest

from interop_helpers import ROOT, free_ports, start, stop, corrective_reading
from test_interop_mavutil import long_scenario

try:
    import mavsdk  # noqa: F401  (a stock client: the dev extra installs it)
except ImportError:
    if os.environ.get("DAA_SIL_REQUIRE_INTEROP"):  # CI: a missing stock client is a failure, not a skip
        raise
    pytest.skip("MAVSDK-Python is in the dev extra: pip install -e '.[dev]'", allow_module_level=True)


async def _first(agen, pred=lambda x: True, timeout: float = 10.0):
    async def run():
        async for x in agen:
            if pred(x):
                return x
    return await asyncio.wait_for(run(), timeout)


def test_mavsdk_reads_the_picture_and_sets_a_parameter(tmp_path):
    from mavsdk.asyncio import Autopilot, ComponentType, Configuration, Mavsdk, Vehicle
    from mavsdk.asyncio.plugins.action import ActionAsync
    from mavsdk.asyncio.plugins.param import ParamAsync
    from mavsdk.asyncio.plugins.telemetry import FlightMode, TelemetryAsync
    from mavsdk.plugins.param import ParamError

    from daa_sil.geometry.frames import enu_to_geodetic
    from daa_sil.sil.scenario import load_scenario
    from daa_sil.geometry.units import G0

    sc = load_scenario(ROOT / "scenarios" / "head_on.yaml")
    (port,) = free_ports(1)
    veh = start(["vehicle", long_scenario(tmp_path), *corrective_reading(tmp_path), "--out", f"udp:127.0.0.1:{port}", "--speed", "2",
                 "--steplog", tmp_path / "steplog.parquet"], tmp_path / "vehicle.log")
    result = {}

    async def session():
        cfg = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
        async with Mavsdk(cfg) as m:
            await m.add_any_connection(f"udpin://127.0.0.1:{port}")
            system = await m.first_autopilot(timeout_s=20.0)
            assert system is not None, "MAVSDK found no autopilot"
            result["identity"] = (await system.autopilot_type(), await system.vehicle_type())
            tel, par, act = TelemetryAsync(system), ParamAsync(system), ActionAsync(system)
            pos = await _first(tel.subscribe_position())
            result["position"] = pos
            # a stock goto: MAVSDK asks for GUIDED, then sends DO_REPOSITION; the vehicle turns east
            lat, lon, alt = enu_to_geodetic(20000.0, 0.0, 1000.0, sc.origin.lat_deg, sc.origin.lon_deg, sc.origin.alt_m)
            await asyncio.wait_for(act.goto_location(float(lat), float(lon), float(alt), 90.0), 15.0)
            result["turn"] = await _first(tel.subscribe_attitude_euler(), lambda a: a.roll_deg > 1.0)
            result["mode"] = await _first(tel.subscribe_flight_mode())
            result["health"] = await _first(tel.subscribe_health(), lambda h: h.is_home_position_ok)
            result["home"] = await tel.home()
            result["wt0"] = await par.get_param_float("DAA_WT")
            await par.set_param_float("DAA_WT", 6.0)
            result["wt1"] = await par.get_param_float("DAA_WT")
            result["enable"] = await par.get_param_int("DAA_ENABLE")
            for name, value in (("DAA_WT", 500.0), ("DAA_WAIT_CONST", 3.0), ("NO_SUCH", 1.0)):
                try:
                    await par.set_param_float(name, value)
                    result[name] = "accepted"
                except ParamError as exc:
                    result[name] = exc.result.name
            result["wt2"] = await par.get_param_float("DAA_WT")

    try:
        asyncio.run(asyncio.wait_for(session(), 90.0))
    finally:
        code = stop(veh)
    assert code == 130, (tmp_path / "vehicle.log").read_text()[-2000:]
    assert result["identity"] == (Autopilot.ARDUPILOT, Vehicle.FIXED_WING)
    pos = result["position"]
    assert abs(pos.latitude_deg - sc.origin.lat_deg) < 0.2 and abs(pos.longitude_deg - sc.origin.lon_deg) < 0.2
    assert abs(pos.absolute_altitude_m - (sc.origin.alt_m + 1000.0)) < 1.0
    # coordinated turn at the 3 deg/s limit and 55 m/s: tan(phi) = 55 * 0.05236 / g = 0.2937 -> 16.365 deg
    expect = math.degrees(math.atan(55.0 * math.radians(3.0) / G0))
    assert abs(expect - 16.365) < 0.001 and abs(result["turn"].roll_deg - expect) < 0.05, result["turn"]
    assert result["mode"] == FlightMode.UNKNOWN  # see the module docstring
    h = result["health"]
    assert h.is_global_position_ok and h.is_local_position_ok and h.is_home_position_ok and h.is_armable
    home = result["home"]
    assert abs(home.absolute_altitude_m - (sc.origin.alt_m + 1000.0)) < 1.0 and abs(home.latitude_deg - 37.4) < 0.2
    assert (result["wt0"], result["wt1"], result["enable"], result["wt2"]) == (4.0, 6.0, 1, 6.0)
    # refusals as MAVSDK names them (the vehicle's PARAM_ERROR, ahead of the PARAM_VALUE with the value kept);
    # on main each was TIMEOUT, after MAVSDK had sent the PARAM_SET five more times
    assert (result["DAA_WT"], result["DAA_WAIT_CONST"], result["NO_SUCH"]) == (
        "VALUE_OUT_OF_RANGE", "READ_ONLY", "DOES_NOT_EXIST")
    import json

    from daa_sil.steplog import steplog_metadata

    ev = json.loads(steplog_metadata(tmp_path / "steplog.parquet")["settings"])
    assert ("mode", "GUIDED", "accepted") in [(e["kind"], e["name"], e["status"]) for e in ev]
    assert [e["new"] for e in ev if e["name"] == "DAA_WT" and e["status"] == "accepted"] == [6.0]
    assert [e["status"] for e in ev if e["name"] == "DAA_WT" and e["status"] != "accepted"] == ["out_of_range"]


def test_mavsdk_sees_the_agent_use_a_wt_it_set(tmp_path):
    """W_T raised to 60 s from MAVSDK before the encounter's first decision (t = 28 s, map wait 54 s):
    the agent then does not wait but hands control to the onboard DAA, and MAVSDK's status text says so."""
    from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
    from mavsdk.asyncio.plugins.param import ParamAsync
    from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

    from daa_sil.steplog import read_steplog

    (port,) = free_ports(1)
    veh = start(["vehicle", long_scenario(tmp_path), *corrective_reading(tmp_path), "--out", f"udp:127.0.0.1:{port}", "--speed", "2",
                 "--steplog", tmp_path / "steplog.parquet"], tmp_path / "vehicle.log")
    texts: list = []

    async def session():
        async with Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION)) as m:
            await m.add_any_connection(f"udpin://127.0.0.1:{port}")
            system = await m.first_autopilot(timeout_s=20.0)
            tel, par = TelemetryAsync(system), ParamAsync(system)
            await par.set_param_float("DAA_WT", 60.0)
            st = await _first(tel.subscribe_status_text(), lambda s: "authority" in s.text, 60.0)
            texts.append(st.text)

    try:
        asyncio.run(asyncio.wait_for(session(), 90.0))
    finally:
        stop(veh)
    assert "authority pilot->daa (no_wait)" in texts[0], texts
    rows = read_steplog(tmp_path / "steplog.parquet").to_pydict()
    first = next(i for i, d in enumerate(rows["decision"]) if d != "none")
    # the map's wait here would pass the default W_T (4 s) -- it is the raised W_T that says no
    assert rows["decision"][first] == "no_wait" and 4.0 <= rows["wait_s"][first] < 60.0 and not rows["projl"][first]


def test_mavsdk_goto_is_accepted_while_the_agent_waits_and_while_daa_flies(tmp_path):
    """The pilot's flow from a stock GCS whatever the authority: MAVSDK's ``goto_location`` (DO_SET_MODE GUIDED,
    then DO_REPOSITION) while the agent waits (CRUISE) and while the DAA flies (AVOID_ADSB). Both succeed;
    the step log shows each command received and judged by SM(u) at the step it arrived, and the heartbeat
    kept showing who flies. On main GUIDED was TEMPORARILY_REJECTED there, and ``goto_location`` failed.

    The vehicle's clock starts when MAVSDK first speaks (``--wait-gcs``); the authority texts (at most one
    per 5 s, the latest mode) tell the test when to send."""
    from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
    from mavsdk.asyncio.plugins.action import ActionAsync
    from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

    from daa_sil.steplog import read_steplog, steplog_metadata

    (port,) = free_ports(1)
    veh = start(["vehicle", long_scenario(tmp_path), "--out", f"udp:127.0.0.1:{port}", "--speed", "3", "--wait-gcs",
                 "--steplog", tmp_path / "steplog.parquet"], tmp_path / "vehicle.log")
    sent: list = []

    async def session():
        async with Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION)) as m:
            await m.add_any_connection(f"udpin://127.0.0.1:{port}")
            system = await m.first_autopilot(timeout_s=60.0)
            tel, act = TelemetryAsync(system), ActionAsync(system)
            texts = tel.subscribe_status_text()
            for mode in ("CRUISE", "AVOID_ADSB"):
                await _first(texts, lambda s, mode=mode: f"{mode} authority" in s.text, 90.0)
                pos = await _first(tel.subscribe_position())
                # 20 km on along the plan's course (north): the agent judges it like any pilot command
                await asyncio.wait_for(act.goto_location(pos.latitude_deg + 0.18, pos.longitude_deg,
                                                         pos.absolute_altitude_m, 0.0), 15.0)
                sent.append(mode)
            n = 0  # a few more steps, so the last command's step is in the step log
            async for _ in tel.subscribe_position():
                n += 1
                if n == 4:
                    break

    try:
        asyncio.run(asyncio.wait_for(session(), 180.0))
    finally:
        code = stop(veh)
    log = (tmp_path / "vehicle.log").read_text()
    assert code == 130 and sent == ["CRUISE", "AVOID_ADSB"], log[-3000:]
    rows = read_steplog(tmp_path / "steplog.parquet").to_pydict()
    got = [i for i, r in enumerate(rows["pilot_cmd_received"]) if r]
    assert len(got) == 2, got
    for i, before in zip(got, ("waiting", "daa")):
        assert rows["authority"][i - 1] == before, (i, rows["authority"][i - 3:i + 1])  # who flew when it came
        assert rows["decision"][i] in ("pilot", "blend", "daa_override") and math.isfinite(rows["sm_pilot"][i])
        assert abs(rows["pilot_trk_deg"][i] % 360.0) < 1.0  # the goto's course: north
    ev = json.loads(steplog_metadata(tmp_path / "steplog.parquet")["settings"])
    guided = [(e["status"], e["t_applied"]) for e in ev if e["kind"] == "mode" and e["name"] == "GUIDED"]
    assert [g[0] for g in guided] == ["accepted", "accepted"], guided  # each goto asked for GUIDED first
