"""The wire: the DBC in code, and the buses it travels on.

- ``_codec``: encode and decode every frame by name through cantools, with
  the E2E protection (``_e2e``: CRC-8 SAE J1850 with a data ID per message).
- ``_protocol``: the codes of the DBC's value tables (bench commands, plant
  states) and step-counter unwrapping.
- ``_bus``: opening a python-can bus, the default transport, ``BusSpec``.
- ``_canimport``: python-can imported by the command line without its MF4
  support (asammdf), which is loaded when a ``.mf4`` capture is read.
- ``_busload``: the bus load of the layout per bit rate and PWM rate.
- ``_batch_decode``: vectorised decoding of a whole capture.
- ``_ccodec``: the C code of the DBC and E2E helper for a controller's firmware.
"""
