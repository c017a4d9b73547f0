"""requirements.lock pins every package of requirements*.txt (and their dependencies) to one
version, and the venv the tests run in was installed from it."""

from __future__ import annotations

import re
from importlib import metadata
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
NAME = re.compile(r"^([A-Za-z0-9][A-Za-z0-9._-]*)")


def canonical(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def requirement_names(path: Path) -> set[str]:
    names = set()
    for line in path.read_text().splitlines():
        line = line.split("#", 1)[0].strip()
        if line.startswith("-r "):  # an included file
            names |= requirement_names(path.parent / line[3:].strip())
        elif line:
            names.add(canonical(NAME.match(line).group(1)))  # type: ignore[union-attr]
    return names


def locked_versions() -> dict[str, str]:
    versions = {}
    for line in (ROOT / "requirements.lock").read_text().splitlines():
        if line and not line.startswith("#"):
            name, sep, version = line.partition("==")
            assert sep and version, f"requirements.lock: not an exact pin: {line!r}"
            versions[canonical(name)] = version
    return versions


def test_every_requirement_is_locked_to_one_version() -> None:
    locked = locked_versions()
    for spec in ("requirements.txt", "requirements-interfaces.txt"):
        missing = requirement_names(ROOT / spec) - set(locked)
        assert not missing, f"{spec}: not in requirements.lock (run make lock): {missing}"


def test_dependencies_of_locked_packages_are_locked_too() -> None:
    """Transitive closure: every installed dependency of a locked package is locked."""
    locked = locked_versions()
    unlocked = set()
    for name in locked:
        try:
            requires = metadata.requires(name) or []
        except metadata.PackageNotFoundError:
            continue
        for requirement in requires:
            if "extra ==" in requirement:
                continue
            dependency = canonical(NAME.match(requirement).group(1))  # type: ignore[union-attr]
            try:
                metadata.version(dependency)
            except metadata.PackageNotFoundError:
                continue  # a marker excluded it here
            if dependency not in locked:
                unlocked.add(f"{dependency} (needed by {name})")
    assert not unlocked, f"installed but not in requirements.lock: {sorted(unlocked)}"


def test_the_venv_has_the_locked_versions() -> None:
    drift = {}
    for name, version in locked_versions().items():
        try:
            installed = metadata.version(name)
        except metadata.PackageNotFoundError:
            continue  # e.g. cmake, pip-installed only where the machine has none
        if installed != version:
            drift[name] = (installed, version)
    assert not drift, f"installed vs requirements.lock (run make setup): {drift}"


def test_setup_installs_through_the_lock() -> None:
    makefile = (ROOT / "Makefile").read_text()
    assert re.search(r"^export PIP_CONSTRAINT :=.*\$\(LOCK\)", makefile, re.M)
    assert re.search(r"^\$\(STAMP\):.*\$\(LOCK\)", makefile, re.M)
