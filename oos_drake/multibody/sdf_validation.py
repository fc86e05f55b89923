"""Check SDF files before Drake parses them (Drake only *warns* about an invalid inertia).

:func:`validate_sdf_tree` walks an SDF file and the files it ``<include>``s and raises a
one-line :class:`SdfError` (a ``ValueError``) naming the file and the element:

- a link whose ``<inertial>`` has a non-positive or non-finite mass, an inertia matrix that is
  not positive definite, or principal moments that violate the triangle inequality;
- a required port frame (``D1``, ``D2``, ``D3``, ``J7``, ...) that no included model defines;
- an unreadable file or an ``<include>`` that cannot be resolved.

Example message: ``sdf/hub_RH2.sdf: link 'RH2': inertia not positive definite (eigenvalues
[-1, 2.01, 2.3] kg m^2)``.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np

__all__ = ["SdfError", "validate_sdf_file", "validate_sdf_tree"]


class SdfError(ValueError):
    """Invalid SDF input; the message names the file and the element."""


def _resolve_include(uri: str, directory: Path, source: Path) -> Path:
    if uri.startswith("package://"):
        name = uri.split("/", 3)[-1]
        return directory / name
    if uri.startswith("file://"):
        return Path(uri[len("file://") :])
    return directory / uri


def _float(element: ET.Element | None, tag: str, path: Path, where: str) -> float:
    node = None if element is None else element.find(tag)
    if node is None or node.text is None:
        raise SdfError(f"{path}: {where}: missing <{tag}>")
    try:
        return float(node.text)
    except ValueError:
        raise SdfError(f"{path}: {where}: <{tag}> is not a number ({node.text!r})") from None


def _check_inertial(link: ET.Element, path: Path) -> None:
    name = link.get("name", "?")
    where = f"link '{name}'"
    inertial = link.find("inertial")
    if inertial is None:
        return  # SDF default: 1 kg, unit inertia (valid)
    mass = _float(inertial, "mass", path, where)
    if not np.isfinite(mass) or mass <= 0:
        raise SdfError(f"{path}: {where}: mass must be > 0 kg, got {mass:g}")
    inertia = inertial.find("inertia")
    J = np.zeros((3, 3))
    for tag in ("ixx", "iyy", "izz", "ixy", "ixz", "iyz"):  # i<row><column>; products optional
        if tag[1] == tag[2] or (inertia is not None and inertia.find(tag) is not None):
            i, j = "xyz".index(tag[1]), "xyz".index(tag[2])
            J[i, j] = J[j, i] = _float(inertia, tag, path, where)
    if not np.all(np.isfinite(J)):
        raise SdfError(f"{path}: {where}: inertia has non-finite entries")
    moments = np.linalg.eigvalsh(J)
    tol = 1e-9 * max(1.0, float(abs(moments).max()))
    if moments.min() <= 0:
        raise SdfError(
            f"{path}: {where}: inertia not positive definite (eigenvalues "
            f"{np.array2string(moments, precision=4, separator=', ')} kg m^2)"
        )
    a, b, c = moments
    if a + b < c - tol:
        raise SdfError(
            f"{path}: {where}: principal moments {a:.6g}, {b:.6g}, {c:.6g} kg m^2 violate the "
            "triangle inequality"
        )


def validate_sdf_file(path: str | Path) -> tuple[set[str], list[Path]]:
    """Validate the links of one SDF file.

    Returns
    -------
    (set of str, list of Path)
        Frame names the file defines, and the files it includes.
    """
    path = Path(path)
    try:
        root = ET.parse(path).getroot()
    except FileNotFoundError:
        raise SdfError(f"{path}: file not found") from None
    except ET.ParseError as error:
        raise SdfError(f"{path}: not valid XML ({error})") from None
    frames: set[str] = set()
    includes: list[Path] = []
    for model in root.iter("model"):
        for link in model.findall("link"):
            _check_inertial(link, path)
            frames.add(link.get("name", ""))
        for frame in model.findall("frame"):
            frames.add(frame.get("name", ""))
        for include in model.findall("include"):
            uri = include.findtext("uri")
            if not uri:
                raise SdfError(f"{path}: <include> without <uri>")
            includes.append(_resolve_include(uri.strip(), path.parent, path))
    return frames, includes


def validate_sdf_tree(
    path: str | Path, required_frames: Mapping[str, str] | Iterable[str] = ()
) -> set[str]:
    """Validate an SDF file and everything it includes; check that required frames exist.

    Parameters
    ----------
    path : str or Path
        Top-level SDF file.
    required_frames : mapping or iterable of str
        Frame (or link) names that the tree must define; a mapping ``{frame: file name}``
        says which file must define it (the error then names that file).

    Returns
    -------
    set of str
        All frame and link names found.

    Raises
    ------
    SdfError
        Invalid inertia, missing file, or a missing required frame.
    """
    path = Path(path)
    seen: set[Path] = set()
    frames: set[str] = set()
    per_file: dict[str, set[str]] = {}
    stack = [path]
    while stack:
        current = stack.pop()
        if current in seen:
            continue
        seen.add(current)
        if not current.is_file():
            raise SdfError(f"{current}: file not found (included from the scenario SDF tree)")
        found, includes = validate_sdf_file(current)
        frames |= found
        per_file[current.name] = found
        stack.extend(includes)
    if isinstance(required_frames, Mapping):
        for name, file_name in required_frames.items():
            if name not in per_file.get(file_name, set()):
                owner = path.parent / file_name
                raise SdfError(f"{owner}: port frame '{name}' missing (no <frame name=\"{name}\">)")
    else:
        missing = [name for name in required_frames if name not in frames]
        if missing:
            files = ", ".join(sorted(str(p.name) for p in seen))
            raise SdfError(f"{path}: port frame '{missing[0]}' missing (searched {files})")
    return frames
