"""What QTM's ``getparameters`` replies say (pure): the 3D labels and the 6DOF bodies, for the
tracker and for ``stb doctor``."""

from __future__ import annotations

import xml.etree.ElementTree as ET


def labels_from_xml(xml: bytes | str) -> list[str]:
    """The 3D labels from a ``getparameters 3d`` reply, in QTM's order (at most the 64
    characters a message's label may have: a longer one must not stop every frame)."""
    root = ET.fromstring(xml)
    return [(label.findtext("Name") or "").strip()[:64] for label in root.iter("Label")]


def bodies_from_xml(xml: bytes | str) -> list[str]:
    """The 6DOF bodies' names from a ``getparameters 6d`` reply, in QTM's order."""
    root = ET.fromstring(xml)
    return [(name.text or "").strip() for name in root.findall("*/Body/Name")]
