"""Training shape families: closed meshes of their stated volume, none a benchmark item."""

from __future__ import annotations

import numpy as np
import pytest

from volec.synth import item_names
from volec.synth.families import FAMILIES, family_mesh, training_shapes


def test_thirty_kinds_none_of_them_a_benchmark_item():
    assert len(FAMILIES) >= 30
    assert not set(FAMILIES) & set(item_names())


@pytest.mark.parametrize("name", sorted(FAMILIES))
def test_each_family_meshes_closed_resting_on_the_table(name):
    mesh = family_mesh(name, 0, resolution=72)
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert 29.0 <= mesh.volume * 1e6 <= 401.0  # drawn log-uniform in 30-400 mL
    assert mesh.bounds[0, 2] == pytest.approx(0.0, abs=1e-9)
    # one piece, not a scatter of crumbs: the largest piece holds nearly all the volume
    pieces = mesh.split(only_watertight=False)
    assert max(p.volume for p in pieces) > 0.98 * mesh.volume


def test_seeds_give_other_proportions_and_the_same_seed_the_same_mesh():
    a, b = family_mesh("kiwi", 0, 48), family_mesh("kiwi", 1, 48)
    assert not np.allclose(sorted(a.extents / a.extents.max()),
                           sorted(b.extents / b.extents.max()), atol=0.01)
    np.testing.assert_array_equal(family_mesh("kiwi", 0, 48).vertices, a.vertices)
    assert len(training_shapes(2, families=["kiwi", "plum"])) == 4
