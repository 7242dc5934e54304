"""Procedural objects: valid models, masses from volume × density, handles on the parts."""

import numpy as np
import pytest
import trimesh

from kinemaforge_opt.model import read_urdf, write_urdf
from kinemaforge_opt.synth.objects import GENERATORS, make_object, write_meshes

CATEGORIES = tuple(GENERATORS)


@pytest.mark.parametrize("category", CATEGORIES)
def test_models_are_valid_with_positive_inertia(category):
    for seed in range(3):
        obj = make_object(category, seed)
        model = obj.model
        model.check_dynamics()
        assert model.nq >= 1
        for link in model.links:
            assert link.inertial.is_physically_consistent()
        for j in model.movable_joints:
            assert j.limits.lower == 0.0 and j.limits.upper > 0.2
            assert j.name in obj.handles


@pytest.mark.parametrize("category", CATEGORIES)
def test_mass_is_mesh_volume_times_a_plausible_density(category):
    obj = make_object(category, 1)
    for link in obj.model.links:
        volume = obj.meshes[link.name].volume
        density = link.inertial.mass / volume
        assert 150 < density < 1500, (link.name, density)
        assert np.allclose(link.inertial.com, obj.meshes[link.name].center_mass, atol=1e-9)


def test_dimension_ranges_and_counts():
    heights = [make_object("refrigerator", s).meshes["body"].extents[2] for s in range(5)]
    assert all(1.5 <= h <= 1.9 for h in heights)
    n_drawers = {make_object("drawer", s).model.nq for s in range(12)}
    assert n_drawers == {1, 2, 3}
    n_doors = {make_object("cabinet", s).model.nq for s in range(12)}
    assert n_doors == {1, 2}
    assert [j.type for j in make_object("cabinet_multi", 0).model.movable_joints] == ["revolute", "prismatic"]


def test_seeded_generation_is_reproducible_and_varies():
    a, b, c = make_object("cabinet", 5), make_object("cabinet", 5), make_object("cabinet", 6)
    assert np.array_equal(a.meshes["body"].vertices, b.meshes["body"].vertices)
    assert not np.allclose(a.meshes["body"].extents, c.meshes["body"].extents)


@pytest.mark.parametrize("category", CATEGORIES)
def test_grip_point_is_on_the_moving_part(category):
    obj = make_object(category, 2)
    for jname, h in obj.handles.items():
        assert h.link == obj.model.joint(jname).child
        dist = trimesh.proximity.signed_distance(obj.meshes[h.link], [h.p_link])[0]
        assert dist > -1e-3, f"{jname}: grip point {dist:.4f} m away from the part"  # inside or on it


def test_laptop_lid_opens_upwards_and_door_opens_outwards():
    laptop = make_object("laptop", 0)
    j = laptop.model.joint("lid_joint")
    grip = np.asarray(laptop.handles["lid_joint"].p_link)
    moved = np.cross(j.axis, grip)  # velocity of the grip point per unit q
    assert moved[2] > 0
    door = make_object("cabinet", 0)
    j = door.model.joint("door_joint")
    assert np.cross(j.axis, door.handles["door_joint"].p_link)[1] < 0  # towards the viewer (-y)


def test_meshes_and_urdf_round_trip(tmp_path):
    obj = make_object("cabinet_multi", 0)
    write_meshes(obj, tmp_path)
    write_urdf(obj.model, tmp_path / "model.urdf")
    back = read_urdf(tmp_path / "model.urdf")
    assert back.joint_names == obj.model.joint_names
    for link in back.links:
        mesh = trimesh.load(tmp_path / link.visuals[0].filename, force="mesh")
        assert mesh.volume == pytest.approx(obj.meshes[link.name].volume, rel=1e-6)
        assert link.inertial.mass == pytest.approx(obj.model.link(link.name).inertial.mass)
