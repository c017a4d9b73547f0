"""Object inertia: validation, primitives' closed forms, the tensor object."""

from __future__ import annotations

import numpy as np
import pytest

from grasp_safety_ros.core import InvalidInputError, ObjectInertia, solid_box, solid_cylinder
from grasp_safety_ros.core.model.inertia import (
    TensorObjectGeometry,
    solid_sphere,
    tensor_object_configurations,
)


@pytest.mark.parametrize(
    ("mass", "tensor", "message"),
    [
        (-1.0, np.eye(3), r"object\.mass_kg: must be in \(0"),
        (0.0, np.eye(3), r"object\.mass_kg"),
        (float("inf"), np.eye(3), r"object\.mass_kg: must be finite"),
        (1.0, [[1, 0.5, 0], [0, 1, 0], [0, 0, 1]], "must be symmetric"),
        (1.0, np.diag([1.0, 1.0, -1.0]), "must be positive definite"),
        (1.0, np.diag([1.0, 1.0, 3.0]), "triangle inequality"),
        (1.0, np.eye(2), r"must have shape \[3, 3\]"),
    ],
)
def test_invalid_inertia_is_refused(mass: float, tensor: object, message: str) -> None:
    with pytest.raises(InvalidInputError, match=message):
        ObjectInertia(mass, np.zeros(3), tensor)


def test_inertia_is_read_only() -> None:
    inertia = solid_box(1.0, [0.1, 0.2, 0.3])
    with pytest.raises(ValueError):
        inertia.inertia_about_com_kgm2[0, 0] = 5.0


def test_primitives_match_closed_forms() -> None:
    box = solid_box(12.0, [1.0, 2.0, 3.0])
    np.testing.assert_allclose(np.diag(box.inertia_about_com_kgm2), [13.0, 10.0, 5.0])
    cylinder = solid_cylinder(12.0, 1.0, 2.0)
    np.testing.assert_allclose(np.diag(cylinder.inertia_about_com_kgm2), [7.0, 7.0, 6.0])
    sphere = solid_sphere(5.0, 1.0)
    np.testing.assert_allclose(np.diag(sphere.inertia_about_com_kgm2), [2.0, 2.0, 2.0])


def test_tensor_object_keeps_mass_and_com_while_the_tensor_changes() -> None:
    geometry = TensorObjectGeometry()
    configurations = tensor_object_configurations(geometry)
    assert len(configurations) == 20
    inertias = [geometry.inertia(a, b) for a, b in configurations]
    for inertia in inertias:
        assert inertia.mass_kg == pytest.approx(0.43)
        np.testing.assert_allclose(
            inertia.com_in_object_m, inertias[0].com_in_object_m, atol=1e-15
        )
    # Moving the x rings out by d adds 2 m_ring d^2 to Iyy and Izz, nothing to Ixx.
    (a0, b0), (a1, b1) = configurations[0], configurations[-1]
    assert b0 != b1 or a0 != a1
    low, high = geometry.inertia(a0, b0), geometry.inertia(a1, b0)
    delta = np.diag(high.inertia_about_com_kgm2 - low.inertia_about_com_kgm2)
    expected = 2 * geometry.ring_mass_kg * (a1**2 - a0**2)
    np.testing.assert_allclose(delta, [0.0, expected, expected], atol=1e-15)


def test_tensor_object_refuses_rings_off_the_rods() -> None:
    with pytest.raises(InvalidInputError, match="x_ring_distance_m"):
        TensorObjectGeometry().inertia(0.5, 0.05)
