"""The chain's state from a /joint_states message, matched by joint name (no rclpy): each
refusal is one line naming the field, and makes the monitor's factor 0."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ...core.exceptions import InvalidInputError


class JointIndex:
    """Where each chain joint sits in a JointState's arrays, cached per name list (a driver
    sends the same names in the same order every time)."""

    def __init__(self, chain_joint_names: Sequence[str]) -> None:
        self._chain = tuple(chain_joint_names)
        self._names: tuple[str, ...] | None = None
        self._index: np.ndarray | None = None

    def chain_state(
        self, names: Sequence[str], positions: Sequence[float], velocities: Sequence[float]
    ) -> tuple[np.ndarray, np.ndarray]:
        """Positions [rad or m] and velocities [rad/s or m/s] of the chain joints (n,), chain
        order; joints beyond the chain (a gripper's) are ignored.

        Raises:
            InvalidInputError: a chain joint is missing, a name repeats, an array's length
                differs from ``name``'s, or a chain joint's value is not finite.
        """
        count = len(names)
        for field, values in (("position", positions), ("velocity", velocities)):
            if len(values) != count:
                raise InvalidInputError(
                    f"joint_states.{field}",
                    f"has {len(values)} values for {count} names"
                    + (" (velocities are needed)" if field == "velocity" else ""),
                )
        index = self._lookup(tuple(names))
        q = np.asarray(positions, dtype=float)[index]
        qd = np.asarray(velocities, dtype=float)[index]
        for field, values in (("position", q), ("velocity", qd)):
            bad = np.flatnonzero(~np.isfinite(values))
            if len(bad):
                joint = self._chain[int(bad[0])]
                raise InvalidInputError(
                    f"joint_states.{field}",
                    f"joint '{joint}' is {float(values[bad[0]])}; must be finite",
                )
        return q, qd

    def _lookup(self, names: tuple[str, ...]) -> np.ndarray:
        if names == self._names and self._index is not None:
            return self._index
        where = {name: k for k, name in enumerate(names)}
        if len(where) != len(names):
            repeated = next(name for name in names if names.count(name) > 1)
            raise InvalidInputError("joint_states.name", f"joint '{repeated}' repeats")
        missing = [name for name in self._chain if name not in where]
        if missing:
            raise InvalidInputError(
                "joint_states.name",
                f"chain joint(s) {', '.join(missing)} missing; got {', '.join(names) or 'none'}",
            )
        self._names, self._index = names, np.array([where[name] for name in self._chain])
        return self._index
