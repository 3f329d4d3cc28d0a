"""Volume: millilitres from a closed mesh, and the checks that make the number trustworthy.

In: a ``trimesh.Trimesh`` in metres. Out: its enclosed volume in millilitres (1 mL = 1e-6 m^3),
or an :class:`OpenMeshError` saying what is wrong with it. The volume of a mesh with holes,
inconsistent face orientation or inward faces is not a number anyone should use, so it is never
returned.
"""

from __future__ import annotations

import trimesh

from volec.errors import VolecError

ML_PER_CUBIC_METRE = 1e6


class OpenMeshError(VolecError):
    """The mesh does not enclose a volume (holes, inconsistent or inward orientation)."""


def closed_mesh_problems(mesh: trimesh.Trimesh) -> list[str]:
    """What keeps ``mesh`` from enclosing a well-defined volume; empty when nothing does."""
    if len(mesh.faces) == 0:
        return ["it has no faces"]
    problems = []
    if not mesh.is_watertight:
        problems.append("it has holes or edges shared by other than two faces (not watertight)")
    if not mesh.is_winding_consistent:
        problems.append("its faces are not consistently oriented")
    if not problems and mesh.volume <= 0:
        problems.append("its faces point inwards (negative volume)")
    return problems


def volume_ml(mesh: trimesh.Trimesh) -> float:
    """The volume enclosed by ``mesh`` (metres) in millilitres; raises
    :class:`OpenMeshError` for a mesh that does not enclose one."""
    problems = closed_mesh_problems(mesh)
    if problems:
        raise OpenMeshError("refusing to take the volume of this mesh: " + "; ".join(problems))
    return float(mesh.volume * ML_PER_CUBIC_METRE)
