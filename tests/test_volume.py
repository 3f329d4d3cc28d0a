"""Volume: exact on closed meshes, refused on open or inward ones."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from volec.volume import OpenMeshError, closed_mesh_problems, volume_ml


def test_volume_of_an_icosphere_matches_its_tetrahedra():
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=0.05)
    # independent: the sum of signed tetrahedra from the origin
    tri = mesh.vertices[mesh.faces]
    tetra = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6
    assert volume_ml(mesh) == pytest.approx(tetra * 1e6, rel=1e-9)
    assert volume_ml(mesh) == pytest.approx(4 / 3 * np.pi * 0.05**3 * 1e6, rel=0.01)


def test_an_open_mesh_is_refused():
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=0.05)
    mesh.update_faces(np.arange(len(mesh.faces)) != 0)  # punch a hole
    assert closed_mesh_problems(mesh)
    with pytest.raises(OpenMeshError, match="not watertight"):
        volume_ml(mesh)


def test_an_inside_out_mesh_is_refused():
    mesh = trimesh.creation.box((0.1, 0.1, 0.1))
    mesh.invert()
    with pytest.raises(OpenMeshError, match="inwards"):
        volume_ml(mesh)


def test_an_inconsistently_oriented_mesh_is_refused():
    mesh = trimesh.creation.box((0.1, 0.1, 0.1))
    faces = mesh.faces.copy()
    faces[0] = faces[0][::-1]
    flipped = trimesh.Trimesh(mesh.vertices, faces, process=False)
    with pytest.raises(OpenMeshError, match="consistently"):
        volume_ml(flipped)
    with pytest.raises(OpenMeshError, match="no faces"):
        volume_ml(trimesh.Trimesh())
