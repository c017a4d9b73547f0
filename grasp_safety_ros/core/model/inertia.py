"""Rigid-body inertia of the grasped object, with primitives and the paper's tensor object."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from ..exceptions import InvalidInputError
from ..input_checks import finite_array, finite_float

SYMMETRY_TOLERANCE = 1e-9
"""Relative tolerance on the asymmetry of an inertia tensor."""


@dataclass(frozen=True)
class ObjectInertia:
    """Inertia of a rigid object, in the object frame.

    Attributes:
        mass_kg: Mass [kg], > 0.
        com_in_object_m: Centre of mass in the object frame [m].
        inertia_about_com_kgm2: 3x3 inertia tensor about the CoM, object axes [kg m^2]:
            symmetric, positive definite, principal moments obeying the triangle inequality.
    """

    mass_kg: float
    com_in_object_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    inertia_about_com_kgm2: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))

    def __post_init__(self) -> None:
        mass = finite_float(self.mass_kg, "object.mass_kg", minimum=0.0, strict_minimum=True)
        com = finite_array(self.com_in_object_m, "object.com_in_object_m", (3,))
        tensor = finite_array(self.inertia_about_com_kgm2, "object.inertia_about_com_kgm2", (3, 3))
        scale = max(float(np.abs(tensor).max()), np.finfo(float).tiny)
        if float(np.abs(tensor - tensor.T).max()) > SYMMETRY_TOLERANCE * scale:
            raise InvalidInputError(
                "object.inertia_about_com_kgm2", f"must be symmetric, got {tensor.tolist()}"
            )
        tensor = 0.5 * (tensor + tensor.T)
        moments = np.linalg.eigvalsh(tensor)
        if moments[0] <= 0.0:
            raise InvalidInputError(
                "object.inertia_about_com_kgm2",
                f"must be positive definite, got principal moments {moments.tolist()}",
            )
        if moments[0] + moments[1] < moments[2] * (1.0 - 1e-9):
            raise InvalidInputError(
                "object.inertia_about_com_kgm2",
                "principal moments must satisfy the triangle inequality (I1 + I2 >= I3), got "
                f"{moments.tolist()}",
            )
        tensor.setflags(write=False)
        object.__setattr__(self, "mass_kg", mass)
        object.__setattr__(self, "com_in_object_m", com)
        object.__setattr__(self, "inertia_about_com_kgm2", tensor)

    def spatial_inertia_in_object(self) -> pin.Inertia:
        """Spatial inertia expressed in the object frame (Pinocchio convention)."""
        return pin.Inertia(
            self.mass_kg, np.array(self.com_in_object_m), np.array(self.inertia_about_com_kgm2)
        )

    def scaled(self, mass_factor: float) -> ObjectInertia:
        """The same shape with mass and inertia scaled by ``mass_factor`` (> 0)."""
        return ObjectInertia(
            self.mass_kg * mass_factor,
            self.com_in_object_m,
            self.inertia_about_com_kgm2 * mass_factor,
        )


def _positive(value: float, name: str) -> float:
    return finite_float(value, name, minimum=0.0, strict_minimum=True)


def solid_box(
    mass_kg: float,
    size_m: Sequence[float],
    com_in_object_m: Sequence[float] | np.ndarray = (0, 0, 0),
) -> ObjectInertia:
    """Uniform box with edge lengths ``size_m`` = (x, y, z) [m] along the object axes."""
    size = finite_array(size_m, "object.box_size_m", (3,))
    if np.any(size <= 0.0):
        raise InvalidInputError("object.box_size_m", f"edges must be > 0, got {size.tolist()}")
    mass = _positive(mass_kg, "object.mass_kg")
    sx, sy, sz = size**2
    tensor = mass / 12.0 * np.diag([sy + sz, sx + sz, sx + sy])
    return ObjectInertia(mass, np.asarray(com_in_object_m, dtype=float), tensor)


def solid_cylinder(
    mass_kg: float,
    radius_m: float,
    length_m: float,
    com_in_object_m: Sequence[float] | np.ndarray = (0, 0, 0),
) -> ObjectInertia:
    """Uniform solid cylinder with its axis along the object z axis."""
    mass = _positive(mass_kg, "object.mass_kg")
    radius = _positive(radius_m, "object.cylinder.radius_m")
    length = _positive(length_m, "object.cylinder.length_m")
    transverse = mass * (3.0 * radius**2 + length**2) / 12.0
    tensor = np.diag([transverse, transverse, 0.5 * mass * radius**2])
    return ObjectInertia(mass, np.asarray(com_in_object_m, dtype=float), tensor)


def solid_sphere(
    mass_kg: float, radius_m: float, com_in_object_m: Sequence[float] | np.ndarray = (0, 0, 0)
) -> ObjectInertia:
    """Uniform solid sphere."""
    mass = _positive(mass_kg, "object.mass_kg")
    radius = _positive(radius_m, "object.sphere.radius_m")
    tensor = np.eye(3) * 0.4 * mass * radius**2
    return ObjectInertia(mass, np.asarray(com_in_object_m, dtype=float), tensor)


@dataclass(frozen=True)
class TensorObjectGeometry:
    """The paper's tensor object, as modelled here (the paper gives only its total mass).

    Five thin rods leave a hub at the object origin along +x (the handle), -x, +y, -y and +z,
    each ``rod_length_m`` long. Five rings (point masses on the rod axes; their own
    moments are neglected, as thin toroids close to the axis) slide along the rods: the +x and
    -x rings sit at the same distance ``a`` from the hub, the +y and -y rings at ``b``, and
    the +z ring at the fixed ``c``. Pairing the rings keeps the centre of mass fixed for
    every (a, b), so the grasp pose relative to the CoM is the same for every configuration
    (as in the paper) while the inertia tensor changes. Total mass 0.43 kg.
    """

    rod_length_m: float = 0.15
    rod_radius_m: float = 0.008
    rod_mass_kg: float = 0.03
    ring_mass_kg: float = 0.056
    z_ring_distance_m: float = 0.10

    @property
    def total_mass_kg(self) -> float:
        """Mass of the five rods and five rings [kg]."""
        return 5.0 * (self.rod_mass_kg + self.ring_mass_kg)

    def inertia(self, x_ring_distance_m: float, y_ring_distance_m: float) -> ObjectInertia:
        """Inertia of the object with the x rings at ``a`` and the y rings at ``b`` [m]."""
        length = self.rod_length_m
        for name, value in (("x", x_ring_distance_m), ("y", y_ring_distance_m)):
            finite_float(value, f"tensor_object.{name}_ring_distance_m", 0.0, length)
        axes = np.eye(3)
        bodies: list[tuple[float, np.ndarray, np.ndarray]] = []  # mass, centre, tensor at centre
        rod = solid_cylinder(self.rod_mass_kg, self.rod_radius_m, length)
        for sign, axis in ((1, 0), (-1, 0), (1, 1), (-1, 1), (1, 2)):
            # Rotate the rod (axis z) onto the object axis `axis`.
            rotation = _rotation_z_onto(axes[axis])
            tensor = rotation @ rod.inertia_about_com_kgm2 @ rotation.T
            bodies.append((self.rod_mass_kg, sign * axes[axis] * length / 2.0, tensor))
        zero = np.zeros((3, 3))
        for sign, axis, distance in (
            (1, 0, x_ring_distance_m),
            (-1, 0, x_ring_distance_m),
            (1, 1, y_ring_distance_m),
            (-1, 1, y_ring_distance_m),
            (1, 2, self.z_ring_distance_m),
        ):
            bodies.append((self.ring_mass_kg, sign * axes[axis] * distance, zero))
        return combine_point_bodies(bodies)


def _rotation_z_onto(axis: np.ndarray) -> np.ndarray:
    """A rotation that maps the z axis onto the unit vector ``axis``."""
    z_axis = np.array([0.0, 0.0, 1.0])
    rotation: np.ndarray = pin.Quaternion.FromTwoVectors(z_axis, axis).toRotationMatrix()
    return rotation


def combine_point_bodies(
    bodies: Sequence[tuple[float, np.ndarray, np.ndarray]],
) -> ObjectInertia:
    """Inertia of rigidly joined bodies given as (mass [kg], CoM [m], tensor about CoM)."""
    total = pin.Inertia.Zero()
    for mass, centre, tensor in bodies:
        total += pin.Inertia(mass, np.asarray(centre, dtype=float), np.asarray(tensor))
    return ObjectInertia(total.mass, total.lever.copy(), total.inertia.copy())


def tensor_object_configurations(
    geometry: TensorObjectGeometry | None = None,
) -> list[tuple[float, float]]:
    """The 20 ring configurations (a, b) [m] used to reproduce the paper: a 5 x 4 grid."""
    geometry = geometry or TensorObjectGeometry()
    length = geometry.rod_length_m
    x_distances = np.linspace(0.02, length - 0.01, 5)
    y_distances = np.linspace(0.02, length - 0.01, 4)
    return [(float(a), float(b)) for a in x_distances for b in y_distances]
