"""The node process's middleware settings (ros/runtime/middleware.py): Fast DDS pointed at the
bundled profile only when nothing else configures it, and the profile one Fast DDS loads."""

from __future__ import annotations

import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from grasp_safety_ros.ros.runtime.middleware import (
    DEFAULT_PROFILE_FILE,
    OWN_SETTINGS,
    PROFILE_VARIABLE,
    SKIP_DEFAULT_FILE,
    size_shared_memory_for_large_responses,
)

RESPONSE_100X201_BYTES = 1_391_133
"""bench/service.py's node-default 100 x 201 response (docs/performance_pipeline.md)."""
NAMESPACE = {"p": "http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"}


def _segment_size(path: str) -> int:
    """The profile's shared-memory segment size [bytes]."""
    root = ET.parse(path).getroot()
    return int(root.findtext(".//p:segment_size", namespaces=NAMESPACE) or 0)


def test_the_profile_is_set_when_nothing_configures_fast_dds(tmp_path: Path) -> None:
    """Its shared-memory segment holds a 100 x 201 response twice (the node writes a response
    while a slow reader may still hold the previous one), and it keeps
    the default transports (shared memory, UDPv4) as the participant's default profile."""
    environ: dict[str, str] = {}
    path = size_shared_memory_for_large_responses(environ, tmp_path)
    assert path is not None and environ == {PROFILE_VARIABLE: path}
    root = ET.parse(path).getroot()
    kinds = [
        d.findtext("p:type", namespaces=NAMESPACE)
        for d in root.iter(f"{{{NAMESPACE['p']}}}transport_descriptor")
    ]
    assert sorted(kinds) == ["SHM", "UDPv4"]
    assert _segment_size(path) >= 2 * RESPONSE_100X201_BYTES  # one written, one being read
    participant = root.find("p:participant", NAMESPACE)
    assert participant is not None and participant.get("is_default_profile") == "true"


@pytest.mark.parametrize(
    "environ",
    [
        {"RMW_IMPLEMENTATION": "rmw_cyclonedds_cpp"},
        *({name: "/somewhere.xml"} for name in OWN_SETTINGS),
    ],
)
def test_a_process_that_configures_its_middleware_keeps_it(
    environ: dict[str, str], tmp_path: Path
) -> None:
    before = dict(environ)
    assert size_shared_memory_for_large_responses(environ, tmp_path) is None
    assert environ == before


def test_a_profile_in_the_working_directory_is_kept(tmp_path: Path) -> None:
    (tmp_path / DEFAULT_PROFILE_FILE).write_text("<profiles/>")
    environ: dict[str, str] = {}
    assert size_shared_memory_for_large_responses(environ, tmp_path) is None
    assert environ == {}


def test_a_skipped_profile_in_the_working_directory_does_not_count(tmp_path: Path) -> None:
    """Fast DDS ignores the working directory's profile when SKIP_DEFAULT_FILE is set."""
    (tmp_path / DEFAULT_PROFILE_FILE).write_text("<profiles/>")
    environ = {SKIP_DEFAULT_FILE: "1"}
    path = size_shared_memory_for_large_responses(environ, tmp_path)
    assert path is not None and environ == {SKIP_DEFAULT_FILE: "1", PROFILE_VARIABLE: path}


def test_fast_dds_loads_the_profile(tmp_path: Path) -> None:
    """A process with the profile starts rclpy and a node without any Fast DDS error, and the
    shared-memory segment it maps is the profile's size (at least; Fast DDS adds its own
    bookkeeping), not the default 512 KiB: a profile Fast DDS could not parse or apply is
    reported on stderr and ignored, one it never read leaves the default segment."""
    environ: dict[str, str] = {}
    path = size_shared_memory_for_large_responses(environ, tmp_path)
    assert path is not None
    script = (
        "import rclpy; from std_msgs.msg import String; rclpy.init(); "
        "node = rclpy.create_node('middleware_check'); node.create_publisher(String, 'check', 1); "
        "print(open('/proc/self/maps').read()); node.destroy_node(); rclpy.shutdown()"
    )
    inherited = {
        name: value
        for name, value in os.environ.items()
        if name not in (*OWN_SETTINGS, "RMW_IMPLEMENTATION")
    }
    run = subprocess.run(
        [sys.executable, "-c", script],
        env={**inherited, PROFILE_VARIABLE: path, "ROS_DOMAIN_ID": "97"},
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert run.returncode == 0, run.stderr
    assert "error" not in run.stderr.lower(), run.stderr
    mapped = [  # "start-end perms offset device inode path" of each segment's mapping
        line.split() for line in run.stdout.splitlines() if "/dev/shm/fastrtps_" in line
    ]
    sizes = [
        int(end, 16) - int(start, 16)
        for (start, end), name in ((f[0].split("-"), f[-1]) for f in mapped)
        if not name.endswith("_el")
    ]
    assert sizes, "no Fast DDS shared-memory segment mapped"
    assert max(sizes) >= _segment_size(path)
