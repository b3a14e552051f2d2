"""The package's version, written in one place: ``<version>`` of ``package.xml``.

``setup.py`` reads it from there at build time; at run time :data:`__version__` comes from
the ``package.xml`` beside the package where this is a checkout (an editable install,
PYTHONPATH, colcon's ``--symlink-install``), and otherwise from the installed
distribution's metadata (a wheel, a colcon install), which the build took from that file.
The checkout's file goes first because an editable install's metadata keeps the version of
its last ``pip install -e``: after a bump it names the old one.

Loaded on first access of ``threat_planner.__version__`` only (PEP 562), so importing the
package pays for neither the XML parser nor :mod:`importlib.metadata`.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ['__version__', 'package_xml_version', 'version']

#: The distribution and ROS package name.
NAME = 'threat_planner'
#: Where a checkout keeps its package.xml: beside the package folder.
CHECKOUT_PACKAGE_XML = Path(__file__).resolve().parents[1] / 'package.xml'


def package_xml_version(path: str | Path) -> str | None:
    """Return ``<version>`` of the ROS package manifest at `path` if it is this package's.

    None where the file is missing, is not XML, names another package or has no version:
    a folder above an installed package may hold anything.
    """
    import xml.etree.ElementTree as ET
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError):
        return None
    if root.tag != 'package' or (root.findtext('name') or '').strip() != NAME:
        return None
    return (root.findtext('version') or '').strip() or None


def version() -> str:
    """Return the version: the checkout's package.xml, else the installed metadata.

    ``0+unknown`` where neither exists (the sources copied without their manifest).
    """
    found = package_xml_version(CHECKOUT_PACKAGE_XML)
    if found is not None:
        return found
    import importlib.metadata
    try:
        return importlib.metadata.version(NAME)
    except importlib.metadata.PackageNotFoundError:
        return '0+unknown'


__version__ = version()
