"""The application layer: the ``ballbeam`` command and the reports. It is the only part of ``twin`` that sees
``controllers`` and ``calib``; it hands the controller catalogue to the live view (twin.viewer) and the core
(the rest of ``twin``) never imports it (tests/test_layers.py)."""
