"""Issue 20 §13: what ``--help`` promises is what the programs do.

* every example command line in ``daa-sil --help`` and ``daa-gcs --help`` is accepted by the
  program's own argument parser, and ``daa-sil --help`` shows the main jobs (demo, run, campaign);
* the ``daa-gcs`` example that "switches the onboard agent off" sets ``DAA_ENABLE=0`` (the vehicle's
  switch), not ``MODE=GUIDED`` (a mode request the vehicle refuses while the agent flies);
* a ``tcp:`` connection string is refused naming every scheme that is accepted.
"""

from __future__ import annotations

import re
import shlex

import pytest

from daa_sil.errors import UsageError


def _example_lines(epilog: str, prog: str) -> list[tuple[str, list[str]]]:
    """``(comment above, argv)`` of every example line of ``prog`` (``\\`` continuations joined)."""
    text = epilog.replace("\\\n", " ")
    out, comment, in_comment = [], "", False
    for line in text.splitlines():
        s = line.strip()
        if s.startswith("#"):
            comment = (comment + " " + s[1:].strip()) if in_comment else s[1:].strip()
            in_comment = True
            continue
        in_comment = False
        if s.startswith(prog + " "):
            out.append((comment, shlex.split(s)[1:]))
    return out


def test_daa_sil_help_examples_cover_the_main_jobs_and_all_parse():
    from daa_sil.cli import EPILOG, build_parser

    lines = _example_lines(EPILOG, "daa-sil")
    commands = [" ".join(argv[:2]) for _, argv in lines]
    for job in ("demo", "run", "campaign run", "campaign report"):
        assert any(c == job or c.startswith(job + " ") for c in commands), (job, commands)
    parser = build_parser()
    for _, argv in lines:
        parser.parse_args(argv)  # exits (SystemExit 2) on an example the parser does not take


def test_daa_gcs_help_switches_the_agent_off_with_daa_enable():
    from gcs.cli import EXAMPLES, build_parser, parse_setting
    from vehicle import identity
    from vehicle.params import ParamTable
    from daa_sil.config.groups import policy_for_group

    lines = _example_lines(EXAMPLES, "daa-gcs")
    parser = build_parser()
    off = [argv for comment, argv in lines if "switches the onboard agent off" in comment]
    assert off, "no example switches the agent off"
    for _, argv in lines:
        args = parser.parse_args(argv)
        for s in args.settings:
            parse_setting(s)
    for argv in off:
        sets = [parse_setting(s) for s in parser.parse_args(argv).settings]
        assert ("DAA_ENABLE", 0.0) in [(n, v) for _, n, v in sets], sets
        res = ParamTable("do365").set("DAA_ENABLE", 0.0, policy_for_group("ID-1"))
        assert res.status == "accepted" and res.policy.enabled is False  # what the vehicle does with it
    # the example's MODE=GUIDED is accepted while the agent flies, but switches nothing off: the agent
    # still decides who flies (the heartbeat stays AVOID_ADSB), DAA_ENABLE is the switch
    result, _ = identity.mode_request(identity.M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, identity.GUIDED,
                                      identity.AVOID_ADSB)
    assert result == identity.M.MAV_RESULT_ACCEPTED
    for comment, argv in lines:
        if any(re.search(r"MODE=", a) for a in argv):
            assert "never switches the agent off" in comment and "switches the onboard agent off" not in comment, comment


@pytest.mark.parametrize("text", ["tcp:127.0.0.1:5760", "tcpin:0.0.0.0:5760", "serial:/dev/ttyUSB0"])
def test_unsupported_scheme_names_every_accepted_one(text):
    from daa_sil.sil.connstr import SEND, parse_connection

    with pytest.raises(UsageError) as info:
        parse_connection(text, "--out", SEND)
    msg = str(info.value)
    assert "udp:" in msg and "udpin:" in msg and "udpout:" in msg and text in msg
    assert "only udp:HOST:PORT is supported" not in msg


def test_vehicle_and_run_examples_parse_and_their_outputs_are_valid():
    """The --out / --vehicle-out examples (issue 20 §12) are accepted by the parsers and the output rules."""
    from daa_sil.cli import build_parser as daa_sil_parser
    from daa_sil.commands.run import EXAMPLES as RUN_EXAMPLES
    from daa_sil.sil.outputs import output_specs
    from vehicle.cli import EXAMPLES as VEHICLE_EXAMPLES, build_parser as vehicle_parser

    vp = vehicle_parser()
    lines = _example_lines(VEHICLE_EXAMPLES, "daa-vehicle")
    assert any(argv.count("--out") >= 3 for _, argv in lines)
    for _, argv in lines:
        args = vp.parse_args(argv)
        output_specs(args.out or ["udp:127.0.0.1:14550"], args.tap, args.tap_writable)
    sp = daa_sil_parser()
    runs = _example_lines(RUN_EXAMPLES, "daa-sil")
    assert any("--vehicle-out" in argv for _, argv in runs)
    for _, argv in runs:
        args = sp.parse_args(argv)
        if getattr(args, "vehicle_outs", None):
            output_specs(["udp:127.0.0.1:1", *args.vehicle_outs], args.tap)
