"""Data files shipped inside the package, found through :mod:`importlib.resources`.

The scenario data (``scenario/data/paper.toml``), the SDF models (``multibody/sdf/``) and the
campaign specs (``campaign/specs/``) are package data (the two folders are links to the
repository's top-level ``sdf/`` and ``campaigns/``; a wheel holds their files): they are found
the same way in a checkout, an editable install and a ``pip install .`` into another
environment, whatever the working directory. Drake and pandas read real files, so a resource is
returned as a filesystem path (a package installed as a zip archive is extracted once per
process).
"""

from __future__ import annotations

import atexit
import contextlib
import importlib.resources
from pathlib import Path

_EXTRACTED = contextlib.ExitStack()
atexit.register(_EXTRACTED.close)


def package_path(package: str, *parts: str) -> Path:
    """Filesystem path of the data file or folder ``parts`` inside ``package``.

    Parameters
    ----------
    package : str
        Dotted package name (``"oos_drake.multibody"``).
    *parts : str
        Path components inside the package (``"sdf"``, ``"oos_scenario.sdf"``).

    Examples
    --------
    >>> package_path("oos_drake.scenario", "data", "paper.toml").name
    'paper.toml'
    """
    resource = importlib.resources.files(package).joinpath(*parts)
    if isinstance(resource, Path):
        return resource
    return _EXTRACTED.enter_context(importlib.resources.as_file(resource))
