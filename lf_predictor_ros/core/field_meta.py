"""Field metadata of the settings dataclasses: description and unit.

Read by the ROS parameter helper (`nodes.params`). A module of its own, free of heavy imports,
so that message conversions importing a settings dataclass do not pull in scipy.
"""
from __future__ import annotations


def field_doc(doc: str, unit: str = '') -> dict[str, str]:
    """``dataclasses.field`` metadata: what the field means and its unit."""
    return {'doc': doc, 'unit': unit}
