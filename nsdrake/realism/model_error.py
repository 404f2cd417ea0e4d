"""Model error: the controller's model of the arm with its masses off by a fraction
(the realism ladder's ``model_error`` rung)."""

from __future__ import annotations

import re

_INERTIAL = re.compile(r"<inertial\b.*?</inertial>", re.DOTALL)
_MASS = re.compile(r'(<mass\b[^>]*\bvalue\s*=\s*")([^"]+)(")')
_INERTIA = re.compile(r'(\bi(?:xx|xy|xz|yy|yz|zz)\s*=\s*")([^"]+)(")')


def scale_urdf_masses(urdf_text: str, factor: float) -> str:
    """The URDF with every link's mass and inertia tensor multiplied by ``factor``
    (a link of the same shape, denser or lighter); centres of mass, kinematics and
    everything else unchanged, text outside the ``<inertial>`` elements untouched
    (an XML round trip would rename the ``drake:`` tags). ``factor`` must be > 0."""
    if not factor > 0:
        raise ValueError(f"the mass factor must be > 0, got {factor}")

    def scale(match: re.Match) -> str:
        return f"{match.group(1)}{float(match.group(2)) * factor!r}{match.group(3)}"

    def scale_inertial(block: re.Match) -> str:
        return _INERTIA.sub(scale, _MASS.sub(scale, block.group(0)))

    return _INERTIAL.sub(scale_inertial, urdf_text)
