"""Scenario files: the YAML schema (:mod:`.schema`), the loader/validator with ``file:line: field``
errors (:mod:`.loader`), the conversion to the core's inputs (:mod:`.convert`) and the expectation
checker (:mod:`.expect`). The schema itself is documented in :mod:`daa_sil.sil.scenario.schema`."""

from .convert import delay_models, delay_spec_string, encounter_set, link_legs, ownship_state
from .expect import check_expectation
from .loader import dump_scenario, load_scenario, parse_scenario, save_scenario, scenario_from_dict
from .schema import (DECISIONS, FAULT_PROCESSES, AllocationSpec, IntruderGeometry, Expectation, InitialState, IntruderSpec,
                     LinkSpec, Maneuver, Origin, Outage, PilotSpec, ProcessFault, Scenario, ScriptedCommand)


__all__ = ["Scenario", "InitialState", "IntruderGeometry", "Maneuver", "IntruderSpec", "LinkSpec", "Outage",
           "PilotSpec", "ScriptedCommand", "AllocationSpec", "Expectation", "Origin", "DECISIONS",
           "ProcessFault", "FAULT_PROCESSES",
           "parse_scenario", "load_scenario", "scenario_from_dict", "dump_scenario", "save_scenario",
           "delay_models", "delay_spec_string", "link_legs", "check_expectation", "encounter_set", "ownship_state"]
