"""A per-group setting is one definition: registering a :class:`~daa_sil.config.settings.Setting`
(here a dummy, ``dummy_gain_s``) makes it a field of the agent's policy, a ``campaign run`` and
``daa-vehicle`` flag, a key of a run configuration, a group file and a scenario, and a MAVLink
parameter, each checked against its one range, and each reaching the consumer: the policy rows
:func:`daa_sil.agent.step.agent_step` is handed every step (spied on, in fast-time and in the vehicle).

The policy's fields are built when :mod:`daa_sil.config.policy` is first imported, so the dummy is
registered in a fresh interpreter (a bounded child process) before anything else of ours.
"""

from __future__ import annotations

import json
import sys
import textwrap
from pathlib import Path

from bounded import run

ROOT = Path(__file__).resolve().parents[1]

CHILD = textwrap.dedent('''
    import json, sys
    from pathlib import Path

    from daa_sil.config.settings import Setting, register

    DUMMY = register(Setting("dummy_gain_s", 3.0, "s", 0.0, 50.0, "a dummy per-group setting", flag="--dummy-gain",
                             aliases=("dummy_gain",), mavlink="DAA_DUMMY", section="allocation", per_group=True))

    import daa_sil.agent.step as agent

    seen = []
    real_step = agent.agent_step

    def spy(t, own, intr, pilot, memory, pol, *args, **kw):  # the consumer: what the agent is handed
        seen.append(float(pol.dummy_gain_s[0]))
        return real_step(t, own, intr, pilot, memory, pol, *args, **kw)

    agent.agent_step = spy
    tmp = Path(sys.argv[1])
    out = {}

    from daa_sil.cli import main

    def campaign(name, *argv):
        seen.clear()
        rc = main(["campaign", "run", "--encounters", "2", "--duration", "20", "--workers", "1", "--no-progress",
                   "--out", str(tmp / name), *argv])
        meta = json.loads((tmp / name / "campaign.json").read_text()) if rc == 0 else {}
        return {"rc": rc, "agent": sorted(set(seen)), "settings": meta.get("config", {}).get("settings"),
                "groups": {g: d.get("dummy_gain_s") for g, d in meta.get("groups", {}).items()}}

    # fast-time: the default, a flag, a run configuration (new and old key), a group file, flag over file
    out["default"] = campaign("default", "--groups", "IC-1")
    out["flag"] = campaign("flag", "--groups", "IC-1", "--dummy-gain", "7")
    (tmp / "run.yaml").write_text("allocation: {dummy_gain_s: 8}\\n")
    out["config"] = campaign("config", "--groups", "IC-1", "--config", str(tmp / "run.yaml"))
    (tmp / "old.yaml").write_text("allocation: {dummy_gain: 8.5}\\n")
    out["config_old_key"] = campaign("config-old", "--groups", "IC-1", "--config", str(tmp / "old.yaml"))
    (tmp / "groups.yaml").write_text("IC-9: {base: IC-1, dummy_gain_s: 9}\\n")
    out["group_file"] = campaign("groups", "--groups", str(tmp / "groups.yaml"))
    out["flag_over_config"] = campaign("both", "--groups", "IC-1", "--config", str(tmp / "run.yaml"),
                                       "--dummy-gain", "6")
    out["out_of_range"] = main(["campaign", "run", "--groups", "IC-1", "--dummy-gain", "51",
                                "--out", str(tmp / "bad")])

    # the vehicle: a scenario's key, then the vehicle's flag over it, then a PARAM_SET, as bytes
    sys.path.insert(0, sys.argv[2])
    from core_helpers import PILOT, vehicle_protocol
    from daa_sil.config.overrides import Overrides
    from daa_sil.link.codec import MavCodec
    from daa_sil.link.codec import mavlink as M
    from daa_sil.sil.scenario import parse_scenario
    from vehicle.cli import build_parser
    from vehicle.core import VehicleCore

    SCENARIO = """\\
    name: dummy
    seed: 3
    duration_s: 20
    ownship: {alt_m: 1000, gs_mps: 55, track_deg: 0}
    intruders:
      - callsign: HEAD1
        initial: {x_m: 150, y_m: 6900, alt_m: 1000, gs_mps: 60, track_deg: 180}
    link: {up: "const:1", down: "const:1"}
    pilot: {mode: scripted, commands: [{t_s: 18, until_s: 19, track_deg: 30}]}
    allocation: {group: IC-1, dummy_gain_s: 11}
    """
    sc = parse_scenario(SCENARIO, "dummy.yaml")
    out["scenario_allocation"] = sc.allocation.settings.given()

    def fly(plant, steps, before=None):
        seen.clear()
        p = vehicle_protocol(sc, plant=plant)
        for k in range(steps):
            if before is not None:
                before(p, k)
            p.begin_step(k)
            p.process()
            p.publish(p.t, p.plant.step(p.t), float(k))
        return p, list(seen)

    _, out["scenario"] = fly(VehicleCore(sc), 2)
    flags = Overrides.from_args(build_parser().parse_args(["dummy.yaml", "--dummy-gain", "12"]))
    _, out["vehicle_flag"] = fly(VehicleCore(sc, flags=flags), 2)

    gcs = MavCodec(255, 190)

    def param_set(p, k):
        if k == 2:
            p.receive(0, gcs.encode(M.MAVLink_param_set_message(1, 1, b"DAA_DUMMY", 13.0,
                                                                       M.MAV_PARAM_TYPE_REAL32)), PILOT, k + 0.5)
        if k == 4:  # out of its range: refused, the value holds
            p.receive(0, gcs.encode(M.MAVLink_param_set_message(1, 1, b"DAA_DUMMY", 60.0,
                                                                       M.MAV_PARAM_TYPE_REAL32)), PILOT, k + 0.5)

    p, out["param_set"] = fly(VehicleCore(sc), 6, param_set)
    out["param_events"] = [(e.name, e.status) for e in p.events if e.kind == "param"]
    print("RESULT " + json.dumps(out))
''')


def test_a_registered_setting_is_set_from_every_input_and_reaches_the_agent(tmp_path):
    script = tmp_path / "child.py"
    script.write_text(CHILD)
    done = run([sys.executable, str(script), str(tmp_path), str(ROOT / "tests")], ROOT, timeout=900,
               env={"PYTHONDONTWRITEBYTECODE": "1", "DAA_SIL_CACHE": str(tmp_path / "cache")})
    line = next((x for x in (done.stdout or "").splitlines() if x.startswith("RESULT ")), None)
    assert done.returncode == 0 and line, (done.returncode, done.stdout[-2000:], done.stderr[-4000:])
    got = json.loads(line[len("RESULT "):])

    def ran(key, value, group="IC-1"):
        r = got[key]
        assert r["rc"] == 0, (key, r)
        assert r["agent"] == [value], (key, r)  # every step of every encounter flew it
        assert r["groups"] == {group: value}, (key, r)  # and campaign.json's groups record it

    ran("default", 3.0)
    assert got["default"]["settings"] == {}
    ran("flag", 7.0)
    assert got["flag"]["settings"] == {"dummy_gain_s": 7.0}
    ran("config", 8.0)
    ran("config_old_key", 8.5)
    ran("group_file", 9.0, "IC-9")
    ran("flag_over_config", 6.0)
    assert got["out_of_range"] == 2
    assert "--dummy-gain must be a number within [0, 50], got 51" in done.stderr
    assert "allocation.dummy_gain is now called allocation.dummy_gain_s" in done.stderr

    assert got["scenario_allocation"] == {"dummy_gain_s": 11.0}
    assert got["scenario"] == [11.0, 11.0]
    assert got["vehicle_flag"] == [12.0, 12.0]  # the command line wins over the scenario
    # the PARAM_SET received before step 2's boundary holds from step 2; the out-of-range one changes nothing
    assert got["param_set"] == [11.0, 11.0, 13.0, 13.0, 13.0, 13.0]
    assert got["param_events"] == [["DAA_DUMMY", "accepted"], ["DAA_DUMMY", "out_of_range"]]


def test_a_per_group_setting_registered_too_late_is_refused():
    """The policy's fields are built on import: a later registration would be silently ignored, so it
    is refused with one line instead."""
    import pytest

    import daa_sil.config.policy  # noqa: F401 -- imported: the fields are built
    from daa_sil.config.settings import ALL, Setting, register
    from daa_sil.errors import UsageError

    late = Setting("late_s", 1.0, "s", 0.0, 2.0, "too late", section="allocation", per_group=True)
    with pytest.raises(UsageError, match="before daa_sil.config.policy is imported"):
        register(late)
    assert "allocation.late_s" not in ALL
    with pytest.raises(UsageError, match="--wt already names another setting"):
        register(Setting("other_s", 1.0, "s", 0.0, 2.0, "a clash", flag="--wt", section="study"))
