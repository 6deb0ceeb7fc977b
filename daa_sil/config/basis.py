"""What each setting of the ``paper`` reading rests on: the one definition ``campaign.json`` records
(``basis``) and the study page prints.

Every row (:class:`Basis`) names a setting, its value under ``paper``, and its **kind**:

* ``text`` -- a quoted sentence of the paper says so;
* ``inference`` -- we infer it, from a sentence (``quote``) or from a number the paper publishes
  (``reasoning`` shows the arithmetic). A number used this way is listed in ``uses`` (finding ids,
  ``id@group``): under the reading that makes the inference, that finding is *input*, never counted
  as a reproduction;
* ``choice`` -- the paper says nothing; the value is ours (``reasoning`` says why).

``alternatives`` names the readings (or sweeps and experiments) that show the other values, and says
which of them a sentence contradicts. :func:`basis_records` gives the rows of any reading: a row whose
settings differ from ``paper``'s is marked ``differs`` and carries that reading's values.
"""

from __future__ import annotations

from dataclasses import dataclass

#: the kinds of basis, in the order the page explains them
KINDS = ("text", "inference", "choice")


@dataclass(frozen=True)
class Basis:
    """The basis of one setting of the ``paper`` reading (see the module docstring)."""

    setting: str  #: what is set, in words
    keys: tuple  #: the :class:`~daa_sil.config.readings.Reading` fields it is (empty: a fixed setting of the code)
    value: str  #: its value under ``paper``, in words
    kind: str  #: :data:`KINDS`
    quote: str = ""  #: the paper's sentence(s), with where they stand
    reasoning: str = ""  #: the inference's arithmetic, or why we chose the value
    alternatives: str = ""  #: readings / sweeps / experiments with the other values
    uses: tuple = ()  #: ``id@group`` of the findings whose published number the inference used

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"basis of {self.setting}: kind must be one of {', '.join(KINDS)}, got {self.kind!r}")
        if self.kind == "text" and not self.quote:
            raise ValueError(f"basis of {self.setting}: a 'text' basis needs its quote")
        if self.kind != "text" and not self.reasoning:
            raise ValueError(f"basis of {self.setting}: an inference or a choice needs its reasoning")


_GRID = ("Simulation Parameters: \"The state space ranges from -1500 m to 1500 m for ΔX and ΔY, -200 m to 200 m for "
         "d_h, 70 m/s to 300 m/s for v_i and -5 m/s to 5 m/s for V_h. The numbers of bins for discretizing the "
         "states are 12, 12, 4, 5, 5, 5, respectively.\"")

#: the basis of every setting of ``paper``, in the order of the paper's method
PAPER_BASIS: tuple[Basis, ...] = (
    Basis("wait-map grid", ("waitmap",), "the paper grid: ΔX, ΔY ±1,500 m (12 bins each), d_h ±200 m (4), "
          "v_i 70-300 m/s (5), V_h ±5 m/s (5), θ_i 5 bins over the full circle", "text", _GRID,
          "θ_i's range is not given: the full circle is ours", "`paper-alerting`: our DO-365 alerting-region grid"),
    Basis("the maps' horizon H (the largest wait a map holds)", ("wait_horizon_s",), "40 s", "inference",
          "Generate the Wait Maps: \"The maximum wait time is 40 seconds and the minimum wait time is 1 second.\"",
          "a state from which LoWC cannot be reached within H waits H, so a map's largest wait is its horizon: the "
          "published maximum gives H = 40 s (the wait-map histogram's maximum is then input, not a result)",
          "`paper-h60`: H = 60 s, a 60 s maximum, against the sentence"),
    Basis("the wait time of a state", (), "W = E[T_LoWC given LoWC within H] under the waiting chain; W = H where "
          "P(LoWC within H) < 10⁻³; W = 0 where evading is optimal or in LoWC", "inference",
          "Formulation of the MDP: \"For every state, we propagate every possible path to the LoWC state and obtain "
          "the corresponding LoWC probability. Assuming that the path is acyclic, the expected waiting time for that "
          "state is calculated as the average of the waiting times of all the paths leading to LoWC weighted by "
          "their probabilities.\"",
          "the path-weighted mean is the text; the 10⁻³ floor (a state that almost never reaches LoWC is no threat "
          "and waits H) and 0 where the MDP evades are ours: the paper does not say what a state that cannot reach "
          "LoWC waits. The published minimum of 1 s is one step to LoWC; ours is 0 at evade-optimal states; both "
          "are below W_T = 4 s, so no decision depends on it",
          "`waitmap build --definition until_evade` (time until LoWC or an evade-optimal state)"),
    Basis("the wait outside the map's box", ("outside",), "approach: the straight-line time to enter the box plus "
          "the wait at the entry point, at most H; H when the state never enters", "inference",
          "Implementation of the Wait Maps: \"the agent matches the current state with a state in the wait map\"; "
          "Generate the Wait Maps: \"The decrease in the wait time is observed as the relative X distance reduces.\"",
          "the text gives no rule beyond the ±1,500 m box, where most states of an encounter lie; the sentence "
          "requires the wait not to grow as the intruder closes, so outside the box it is at least the wait where the "
          "intruder will enter the box and at most the maps' maximum. Of the rules that satisfy it, ours meets the "
          "map's value at the box's edge",
          "`paper-outside-far`: w = H outside (also allowed); `paper-clamp`: the nearest box state, whose wait stays "
          "that of the edge while ΔX shrinks from 10 km to 1.5 km (against the sentence)"),
    Basis("what a group's latency is", ("latency",), "the round trip, split evenly between the links", "inference",
          "Problem Formulation: \"The round-trip latency duration can be in the range of 0.2 to 10 seconds\"",
          "the only sentence on what the latency measures; the group table gives one value per group (4 s, 5 s, "
          "Gaussian), read as that round trip", "`paper-one-way`: the value on each link (doubles the round trip)"),
    Basis("how the Gaussian delay varies", ("delay_draw",), "redrawn every 10 s, N(5, 3) truncated to 0.2-10 s",
          "inference",
          "Pilot Command Incorporation: \"Comparing the time varying latency groups B-2 and ID-2\"; Implementation "
          "of the Wait Maps: \"The latency is varied according to a Gaussian distribution with a mean around 5 sec "
          "and a standard deviation of 3 sec.\"",
          "'time varying' means the delay changes within an encounter; how often it is redrawn is not given: every "
          "10 s is ours (a draw per packet under first-in-first-out delivery raises the mean delay to 8.3 s); the "
          "truncation is the round-trip range above",
          "`paper-delay-per-encounter`: one draw per encounter (constant in time: against 'time varying')"),
    Basis("when the pilot streams", ("pilot_start", "pilot_stop"), "one command a step from the first telemetry it "
          "sees until safe avoidance", "text",
          "Implementation of the Wait Maps: \"The model captures pilot response from the beginning of an encounter "
          "till safe avoidance.\"",
          "safe avoidance is detected by our test (no alert on the pilot's display, every intruder past its closest "
          "point of approach): the paper does not say how", "`detection`: to the end of the encounter; `extended`: "
          "from the corrective alert"),
    Basis("what the pilot streams before it maneuvers", ("hold_commands",), "the course it sees ('hold')",
          "inference", "",
          "the reception table's B-1 row: 795,163 received / 10,000 encounters = 79.5 commands per 240 s encounter "
          "(the same number is the execution table's Pilot column); a pilot that sends only its maneuvers sends a "
          "handful per encounter (ours: about 6, `paper-no-hold`), so the paper's pilot also sends commands that are "
          "not maneuvers: we read them as the course it sees, once a step until it maneuvers. No sentence mentions "
          "them",
          "`paper-no-hold`: maneuvers only", ("received@B-1", "pilot-executed@B-1")),
    Basis("when the pilot maneuvers", ("pilot_engage",), "from the corrective alert", "choice",
          "Implementation of the Wait Maps: \"The pilot model uses DAIDALUS to choose avoidance maneuvers.\"",
          "the paper does not say at which alert: DAIDALUS's corrective level is where a maneuver is called for",
          "`paper-preventive`: from the preventive alert"),
    Basis("the pilot's response time", (), "Guendel's model, mean about 19 s", "choice",
          "Implementation of the Wait Maps: \"An unmanned aircraft pilot model [Guendel] is integrated in the "
          "simulator to mimic human-pilot response.\"", "the cited model's parameters (`docs/models.md`)",
          "the sweep `pilot=guendel,nasa_rayleigh5` (a 5 s-mean Rayleigh pilot)"),
    Basis("an unsafe received command", ("unsafe_hold",), "Algorithm 2 in the integrated groups, a DAA override in "
          "the baselines, a 'hold' included", "text",
          "Algorithm 1: \"else pilot command received: if SM(u_p) > 0, u_a ← u_p; else if SM(u_p) < 0, invoke "
          "Algorithm 2\"; Pilot Command Incorporation: \"a DAA override is an instance where the onboard DAA takes "
          "the authority even though a pilot command is available\"",
          "a 'hold' is a received command; without a maneuver intent yet, Algorithm 2 falls to its last step, "
          "\"return any safe avoidance maneuver\"",
          "`paper-hold-none`: an unsafe 'hold' as no command (against Algorithm 1)"),
    Basis("when the agent decides", ("agent_active",), "every step from the start of the encounter until safe "
          "avoidance, and again from a later corrective alert", "inference",
          "Introduction: \"an ownship UAS is in an active encounter with a dynamic intruder\"; Problem Formulation: "
          "\"As the onboard surveillance system detects the intruder, the surveillance information is transmitted to "
          "the pilot\"; Implementation of the Wait Maps: \"from the beginning of an encounter till safe avoidance\"",
          "an encounter begins when the intruder is detected and ends at safe avoidance; our intruders are within "
          "surveillance from t = 0, so the active encounter runs from t = 0 until safe avoidance (the pilot's test, "
          "on the vehicle's truth). No number is used", "`paper-corrective`: from the corrective alert only"),
    Basis("the waiting equation", ("wait_rule",), "wait iff w(S(k)) ≥ W_T and no ProjL, read every step", "text",
          "Design of the Control Allocation Agent: \"Wait if w(S(k)) ≥ W_T and ProjL(i) = 0, ∀i = 1, ..., N\"; "
          "\"The optimal time is updated when the state is transitioned.\"", "",
          "`paper-countdown`: w as a budget counted from the start of a wait"),
    Basis("W_T", (), "4 s", "text", "\"we have chosen W_T = 4 sec given delays between 0.2 and 10 seconds\"", "",
          "the sweep `wt=2,4,8,16`"),
    Basis("ProjL's look-ahead N", (), "25 s", "choice", "\"a loss of well clear within the next N seconds\"",
          "N is not given: the DO-365 warning alerting time", "the setting `allocation.projl_horizon_s`"),
    Basis("the DAA's authority on a step without a command", ("daa_authority",), "Algorithm 1 every step", "text",
          "Design of the Control Allocation Agent: \"The command allocation at any time depends on the status of pilot "
          "command reception, ...\"", "", "`paper-keep-daa` (our extension): the DAA keeps it until no alert"),
    Basis("HMD / VMD units", ("units",), "metres", "text",
          "Intruder Parameters for Trajectory Generation: \"HMD (m) 0 2750 uniform\", \"VMD (m) -915 915 uniform\"",
          "", "`paper-feet`: feet (against the table's labels; measures the unit)"),
    Basis("what 'received' counts", ("window", "received"), "the whole encounter; received = executed as sent + "
          "blended", "inference", "",
          "the reception table equals the execution table's Pilot column in the baselines (B-2: 793,529 = 793,529) "
          "and Pilot + Blending in the integrated groups (ID-2: 853,974 + 68,019 = 921,993). The identity fixes how "
          "the counts relate, not their size, so no count is used up",
          "`--recount NAME:received=arrived` counts every arrival alike"),
    Basis("a command superseded within its step", ("superseded",), "counted, with the fate of the newer command "
          "released with it", "choice", "",
          "the paper counts every command received; after a delay drops, the link releases several commands in one "
          "step and the vehicle flies the newest: the older ones were received, and are counted where the newest "
          "lands (executed as sent, blended, overridden), so received = pilot + blend still holds",
          "`paper-one-per-step`: only the newest counts"),
    Basis("which blends count", ("blends",), "every blend", "text",
          "Command Execution Statistics: the \"Blending\" column", "", "`paper-hold-blend`: blends of maneuvers only"),
    Basis("thresholds, T, ΔT, the ownship", (), "HMD* 1,220 m, d_h* 122 m, τ*_mod 35 s; NMAC 500 ft / 120 ft; "
          "T = 240 s; ΔT = 1 s; 55 m/s due north", "text",
          "\"C_1 = HMD* = 1220, C_2 = d_h* = 122\"; \"R ≤ 500 ft, and H ≤ 120 ft\"; \"We set T = 240 sec.\"; "
          "\"we set ΔT = 1 second\"; \"a constant airspeed of 55 m/s with a heading of 0 degree\"",
          "τ*_mod from DO-365, which the paper cites for the LoWC test", ""),
    Basis("the MDP's reward and discount", (), "C1 = 1,220, C2 = 122, C3 = 1; γ = 0.95", "choice",
          "\"we use C_1 = HMD* = 1220, C_2 = d_h* = 122 and C_3 = 1\"; \"γ < 1 is the discounted factor\"",
          "the constants are the text; γ's value is not given: 0.95 is ours", "the sweep `gamma=0.9,0.95,0.99`"),
    Basis("the intruder model of the MDP", (), "a step is horizontal or vertical with probability ½ each; a map "
          "conditioned on a turn rate keeps it with probability 0.8 a step", "choice",
          "\"we assume that the intruder will take only the vertical or the horizontal maneuver at one time\"; "
          "\"By changing the intruder initial conditions, we obtain different wait maps.\"",
          "neither probability is given: ½ treats the planes alike; 0.8 makes the ±5 °/s maps mirror images with "
          "the 0 °/s map symmetric, as the paper's top views show", "`waitmap build` options"),
    Basis("SM(u), the safety metric", (), "the time to the first predicted LoWC of a command, over 55 s; safe "
          "when positive", "choice", "\"A positive safety metric indicates a safe maneuver.\"",
          "SM is not defined beyond its sign; the 55 s horizon covers the 35 s τ*_mod and a 20 s maneuver",
          "`daa.sm_horizon_s` (the experiments at 35 and 25 s)"),
    Basis("Algorithm 2's search", (), "the DAA's band candidates (track every 5°, vertical speed every 500 fpm, "
          "ground speed every 10 kt), the safe one closest to the pilot's command", "choice",
          "Algorithm 2: \"search for a safe avoidance maneuver from the onboard DAA system that matches (ax,d)\"",
          "the onboard DAA's own candidates (`docs/daa.md`)", "`daa.trk_step`, `daa.vs_step`, `daa.gs_step`"),
    Basis("the intruder's turn", (), "one turn of 90° of heading at the drawn rate, from the advance time", "choice",
          "Intruder Parameters for Trajectory Generation: \"turn rate (dps) -5 5 uniform\", \"advance rate 0 0.8 "
          "Gaussian(0.5,0.5)\"", "the turn's length is not given: 90° is ours", "`EncounterConfig.max_turn_deg`"),
    Basis("which encounters are kept", (), "the CPA at T/2 = 120 s; a draw whose closest pass is elsewhere, or that "
          "starts inside or within 25 s of a well-clear violation, is redrawn", "choice",
          "\"We have generated 10,000 pairs of aircraft trajectories that encompass a wide range of encounter "
          "geometry.\"", "the CPA time is not given; an encounter that starts in conflict gives the agent nothing to "
          "decide", "`EncounterConfig` (`t_cpa_s`, `warning_time_s`)"),
    Basis("stale commands and a lost link", (), "a command older than 15 s is not flown; 20 s without a packet is a "
          "lost link", "choice", "", "the paper says nothing; both exceed the longest round trip (10 s)",
          "the settings `link.stale_command_s`, `link.link_timeout_s`"),
    Basis("intruders per encounter", (), "one", "text", "\"during an encounter with a dynamic intruder aircraft\"",
          "", "the sweep `intruders=1,2`"),
)


def _value(reading, keys) -> dict:
    return {k: getattr(reading, k) for k in keys}


def basis_records(reading) -> list[dict]:
    """The basis rows of ``reading`` (a :class:`~daa_sil.config.readings.Reading`), plain data: a row
    whose settings differ from ``paper``'s is marked ``differs`` with this reading's values."""
    from daa_sil.config.readings import READINGS  # lazy: start-up time

    paper = READINGS["paper"]
    out = []
    for b in PAPER_BASIS:
        mine, theirs = _value(reading, b.keys), _value(paper, b.keys)
        row = {"setting": b.setting, "keys": list(b.keys), "paper_value": b.value, "kind": b.kind, "quote": b.quote,
               "reasoning": b.reasoning, "alternatives": b.alternatives, "uses": list(b.uses),
               "differs": mine != theirs}
        if row["differs"]:
            row["values"] = mine
        out.append(row)
    return out


def consumed_findings(records: "list | None") -> set:
    """``(finding id, group)`` of the findings a reading's inferences used (rows that do not differ from
    ``paper``), from :func:`basis_records` output (None: none)."""
    out = set()
    for r in records or ():
        if r.get("differs"):
            continue
        for u in r.get("uses", ()):
            fid, _, grp = str(u).partition("@")
            out.add((fid, grp or None))
    return out


__all__ = ["Basis", "KINDS", "PAPER_BASIS", "basis_records", "consumed_findings"]
