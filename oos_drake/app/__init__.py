"""The application floor: the ``oos`` command line and the ``oos run`` pipeline.

Every command module (``register(subparsers)``) and the pipeline live here, on top of every
library package; nothing below imports from :mod:`oos_drake.app` (tests/test_architecture.py).
"""
