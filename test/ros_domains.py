"""ROS_DOMAIN_ID allocation for tests and benchmarks that start rclpy contexts or nodes.

Two test suites running at once on one machine must never share a domain (their nodes would
answer each other's requests). A domain is claimed by an exclusive, non-blocking ``flock`` on
its own lock file in a shared directory of the system temp dir; ids are tried in order and the
first free one is taken. The lock is held while the claim is open and is released by the
kernel when the process dies, so a crashed run never leaks a domain.
"""

from __future__ import annotations

import errno
import fcntl
import os
import tempfile
from pathlib import Path
from types import TracebackType

LOCK_DIR = Path(tempfile.gettempdir()) / "grasp_safety_ros_domains"
DOMAIN_IDS = range(1, 102)
"""Domains 1..101: valid with the default port mapping on any platform; 0 is the users'
default domain and left alone."""


class NoFreeDomainError(RuntimeError):
    """Every ROS domain id of DOMAIN_IDS is claimed."""


class DomainClaim:
    """An exclusive claim on one ROS domain id; ``release`` (or leaving ``with``) frees it."""

    def __init__(self, domain_id: int, fd: int) -> None:
        self.domain_id = domain_id
        self._fd: int | None = fd

    def release(self) -> None:
        """Free the domain (idempotent)."""
        if self._fd is not None:
            os.close(self._fd)  # closing the only descriptor drops the flock
            self._fd = None

    def __enter__(self) -> DomainClaim:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.release()


def claim_ros_domain(
    domain_ids: range | list[int] = DOMAIN_IDS, lock_dir: Path = LOCK_DIR
) -> DomainClaim:
    """Claim the first free domain id of ``domain_ids``.

    Raises:
        NoFreeDomainError: all of them are claimed (by this or other processes).
    """
    _make_shared_dir(lock_dir)
    for domain_id in domain_ids:
        path = lock_dir / f"domain_{domain_id}.lock"
        try:
            fd = os.open(path, os.O_RDONLY | os.O_CREAT, 0o666)
        except PermissionError:
            continue  # a file another user created and we cannot open: treat as taken
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as error:
            os.close(fd)
            if error.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                continue
            raise
        return DomainClaim(domain_id, fd)
    raise NoFreeDomainError(
        f"all ROS domain ids {domain_ids[0]}..{domain_ids[-1]} are claimed (locks in {lock_dir})"
    )


def _make_shared_dir(lock_dir: Path) -> None:
    """Create the lock directory writable by every user (sticky, like /tmp)."""
    try:
        lock_dir.mkdir(mode=0o777)
    except FileExistsError:
        return
    try:
        os.chmod(lock_dir, 0o1777)  # mkdir's mode is masked by the umask
    except PermissionError:
        pass
