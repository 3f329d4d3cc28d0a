import numpy as np
import pytest

from volec.metrics import bottom_gap
from volec.synth.shapes import (
    FLAT_BASE_SETTLE_MM,
    ITEMS,
    flat_below,
    item_mesh,
    item_names,
    mesh_field,
)

# Ground-truth volumes (mL) typed from the paper's Table I, independent of volec's own table.
TABLE_I_ML = {
    "apple": 175, "orange": 200, "avocado": 85, "lemon": 140, "donut": 245, "durum": 200,
    "pear": 170, "chocolate_cake": 195, "chocolate_croissant": 275, "samosa": 145,
    "apple_pie": 135, "chocolate_bomb": 200, "empanadilla": 95, "falafel": 48,
    "french_bread": 163, "paxoco_mini": 150, "napolitana": 233, "capsicum": 320,
    "chocolate_panettone": 293, "banana": 150, "yellow_cane": 350,
}


def signed_tetra_volume_ml(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Divergence theorem by hand: the sum of signed tetrahedra from the origin."""
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0 * 1e6)


def test_the_library_is_table_one():
    assert item_names() == list(TABLE_I_ML)
    assert len(ITEMS) == 21


@pytest.mark.parametrize("name", list(TABLE_I_ML))
def test_item_is_watertight_with_table_one_volume(name):
    mesh = item_mesh(name)
    assert mesh.is_watertight and mesh.is_winding_consistent
    volume = signed_tetra_volume_ml(np.asarray(mesh.vertices), np.asarray(mesh.faces))
    assert volume == pytest.approx(TABLE_I_ML[name], rel=1e-3)
    lo, hi = mesh.bounds
    assert lo[2] == pytest.approx(0.0, abs=1e-12)  # rests on the plate
    assert 0.04 < (hi - lo).max() < 0.20  # food-sized: 4 to 20 cm
    assert np.hypot(*((lo + hi)[:2] / 2)) < 1e-9  # centred over the origin


def test_a_second_independent_volume_agrees():
    manifold3d = pytest.importorskip("manifold3d")
    mesh = item_mesh("pear")
    m = manifold3d.Manifold(manifold3d.Mesh(
        vert_properties=np.asarray(mesh.vertices, np.float32),
        tri_verts=np.asarray(mesh.faces, np.uint32),
    ))
    assert m.volume() * 1e6 == pytest.approx(170.0, rel=1e-3)


def test_the_donut_has_a_hole_and_the_apple_has_none():
    # Euler characteristic: 2 for a sphere-like surface, 0 for a torus.
    assert item_mesh("donut").euler_number == 0
    assert item_mesh("apple").euler_number == 2


def test_shapes_are_not_all_spheres():
    # Ratio of the longest to the shortest extent: elongated items are far from 1.
    ratios = {n: (lambda e: e.max() / e.min())(item_mesh(n).extents) for n in TABLE_I_ML}
    assert ratios["banana"] > 2.5 and ratios["french_bread"] > 3
    assert ratios["orange"] < 1.2
    assert ratios["donut"] > 3  # flat ring


def test_items_are_not_mirror_symmetric():
    # Irregular detail: reflecting the orange through its vertical mid-plane does not map it
    # onto itself (its surface deviates by a visible fraction of a millimetre).
    from scipy.spatial import cKDTree

    mesh = item_mesh("orange")
    v = np.asarray(mesh.vertices)
    mirrored = v * np.array([-1.0, 1.0, 1.0])
    d, _ = cKDTree(v).query(mirrored)
    assert np.percentile(d, 90) > 3e-4


def test_meshes_are_deterministic_and_copies():
    a, b = item_mesh("samosa"), item_mesh("samosa")
    np.testing.assert_array_equal(a.vertices, b.vertices)
    a.apply_translation([1, 0, 0])
    assert item_mesh("samosa").bounds[0, 2] == pytest.approx(0.0, abs=1e-12)


def test_unknown_item_names_the_known_ones():
    with pytest.raises(KeyError, match="apple"):
        item_mesh("kiwi")


def test_flat_below_cuts_a_spherical_cap_of_the_analytic_volume():
    # A unit ball cut 0.4 above its lowest point loses a cap of pi h^2 (3 - h) / 3.
    def ball(p):
        return np.linalg.norm(p, axis=1) - 1.0

    h = 0.4
    mesh = mesh_field(flat_below(ball, -1.0 + h), 1.3, resolution=160)
    assert mesh.is_watertight
    expected = 4.0 / 3.0 * np.pi - np.pi * h**2 * (3.0 - h) / 3.0
    assert mesh.volume == pytest.approx(expected, rel=5e-3)
    bottom = mesh.vertices[:, 2].min()
    assert bottom == pytest.approx(-1.0 + h, abs=1e-9)  # the cut face is the plane itself


def underside_contact_share(mesh, touch_m=0.2e-3) -> float:
    """Share of the footprint whose underside lies within ``touch_m`` of the plate (columns
    of :func:`volec.metrics.bottom_gap`, rays straight up from under the plate)."""
    _, gap_m, _ = bottom_gap(mesh, up=np.array([0.0, 0.0, 1.0]))
    return float(np.mean(gap_m < touch_m))


def test_flat_based_items_rest_on_their_base_and_fruit_on_a_point():
    assert ITEMS["apple_pie"].settle_mm == FLAT_BASE_SETTLE_MM > 0
    assert ITEMS["apple"].settle_mm == 0
    assert underside_contact_share(item_mesh("apple_pie")) > 0.9
    assert underside_contact_share(item_mesh("chocolate_cake")) > 0.9
    assert underside_contact_share(item_mesh("apple")) < 0.1
