"""The ROS domain allocator: claims are exclusive while held, freed on release or death."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from ros_domains import DOMAIN_IDS, NoFreeDomainError, claim_ros_domain

TEST_DIR = Path(__file__).resolve().parent


def test_two_claims_never_share_an_id_while_held(tmp_path: Path) -> None:
    claims = [claim_ros_domain(range(1, 6), tmp_path) for _ in range(5)]
    assert sorted(c.domain_id for c in claims) == [1, 2, 3, 4, 5]
    with pytest.raises(NoFreeDomainError, match=r"all ROS domain ids 1\.\.5 are claimed"):
        claim_ros_domain(range(1, 6), tmp_path)
    for claim in claims:
        claim.release()


def test_a_released_id_is_reusable(tmp_path: Path) -> None:
    first = claim_ros_domain(range(1, 4), tmp_path)
    second = claim_ros_domain(range(1, 4), tmp_path)
    assert (first.domain_id, second.domain_id) == (1, 2)
    first.release()
    first.release()  # idempotent
    with claim_ros_domain(range(1, 4), tmp_path) as again:
        assert again.domain_id == 1
    assert claim_ros_domain(range(1, 4), tmp_path).domain_id == 1  # freed by the with block
    second.release()


def test_another_process_holding_an_id_is_skipped_until_it_dies(tmp_path: Path) -> None:
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys; sys.path.insert(0, sys.argv[1]); from pathlib import Path;"
            "from ros_domains import claim_ros_domain;"
            "c = claim_ros_domain(range(1, 4), Path(sys.argv[2])); print(c.domain_id, flush=True);"
            "sys.stdin.read()",
            str(TEST_DIR),
            str(tmp_path),
        ],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout is not None
        assert holder.stdout.readline().strip() == "1"
        with claim_ros_domain(range(1, 4), tmp_path) as claim:
            assert claim.domain_id == 2
    finally:
        holder.kill()  # no release: the kernel drops the lock with the process
        holder.wait(timeout=10)
    with claim_ros_domain(range(1, 4), tmp_path) as claim:
        assert claim.domain_id == 1


def test_default_range_is_valid_for_ros() -> None:
    assert DOMAIN_IDS[0] >= 1 and DOMAIN_IDS[-1] <= 101
    with claim_ros_domain() as claim:
        assert claim.domain_id in DOMAIN_IDS
