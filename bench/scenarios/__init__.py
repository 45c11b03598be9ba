"""Scenarios: the schema, the shipped TOML files, and what a scenario builds.

- ``_schema``: reading and validating a scenario file (``Scenario``); a
  mistake is one line naming the file, the field and the reason.
- ``_setup``: the plant, the controller and the command schedule of a
  scenario, the motor preset it names, its PWM period.
- ``_reference``: what every key means (unit, range, meaning), and
  ``docs/SCENARIOS.md`` rendered from it and the schema (``bench schema``).
- ``_dotted``: a scenario with single keys changed by their dotted name
  (``controller_model.L_q``), for sweeps.
- ``*.toml``: the papers' scenarios, one file each.
"""
