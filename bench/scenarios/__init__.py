"""Scenarios: the schema, the shipped TOML files, and what a scenario builds.

- ``_schema``: reading and validating a scenario file (``Scenario``); a
  mistake is one line naming the file, the field and the reason.
- ``_setup``: the plant, the controller and the command schedule of a
  scenario, the motor preset it names, its PWM period.
- ``*.toml``: the papers' scenarios, one file each.
"""
