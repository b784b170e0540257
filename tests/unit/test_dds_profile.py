"""The project's Fast DDS profile: what the file asks for, who gets it, and that Fast DDS
applies it (the shared-memory segment a process maps has the profile's size)."""
from __future__ import annotations

import os
import socket
import struct
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Dict, List

import pytest
from rclpy.serialization import serialize_message
from sensor_msgs.msg import Image

from ros_common import dds

NS = {'f': 'http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles'}
REPO = Path(__file__).resolve().parents[2]
SOURCE_PROFILE = REPO / 'ros_common' / 'config' / 'fastdds.xml'
NETWORK_PROFILE = REPO / 'ros_common' / 'config' / 'fastdds_network.xml'

# A node with one publisher, alive until its stdin closes.
CHILD = '''
import sys, rclpy
from std_msgs.msg import String
rclpy.init()
node = rclpy.create_node('profile_probe')
node.create_publisher(String, 'profile_probe', 10)
print('ready', flush=True)
sys.stdin.read()
'''


def _frame_bytes(width: int = 640, height: int = 480) -> int:
    return len(serialize_message(Image(width=width, height=height, encoding='rgb8',
                                       step=3 * width, data=bytes(3 * width * height))))


def test_the_profile_gives_shared_memory_a_segment_that_holds_camera_frames():
    root = ET.parse(SOURCE_PROFILE).getroot()
    shm = [d for d in root.iterfind('f:transport_descriptors/f:transport_descriptor', NS)
           if d.findtext('f:type', namespaces=NS) == 'SHM']
    assert len(shm) == 1
    segment = int(shm[0].findtext('f:segment_size', namespaces=NS))
    assert segment == dds.SEGMENT_SIZE
    assert segment >= 8 * _frame_bytes(640, 480)     # eight 640x480 rgb8 frames in flight
    assert segment >= 2 * _frame_bytes(1280, 720)


@pytest.mark.parametrize('source, whitelist', [(SOURCE_PROFILE, ['127.0.0.1']),
                                               (NETWORK_PROFILE, [])])
def test_the_profiles_differ_only_in_holding_udp_to_the_loopback_interface(source, whitelist):
    root = ET.parse(source).getroot()
    types = {d.findtext('f:transport_id', namespaces=NS): d.findtext('f:type', namespaces=NS)
             for d in root.iterfind('f:transport_descriptors/f:transport_descriptor', NS)}
    participant = root.find('f:participant', NS)
    assert participant.get('is_default_profile') == 'true'
    used = [t.text for t in participant.iterfind('f:rtps/f:userTransports/f:transport_id', NS)]
    assert sorted(types[t] for t in used) == ['SHM', 'UDPv4']
    assert participant.findtext('f:rtps/f:useBuiltinTransports', namespaces=NS) == 'false'
    udp, = [d for d in root.iterfind('f:transport_descriptors/f:transport_descriptor', NS)
            if d.findtext('f:type', namespaces=NS) == 'UDPv4']
    assert [a.text for a in udp.iterfind('f:interfaceWhiteList/f:address', NS)] == whitelist
    shm, = [d for d in root.iterfind('f:transport_descriptors/f:transport_descriptor', NS)
            if d.findtext('f:type', namespaces=NS) == 'SHM']
    assert int(shm.findtext('f:segment_size', namespaces=NS)) == dds.SEGMENT_SIZE


def test_the_network_profile_is_chosen_only_when_the_user_asks_for_other_machines():
    local, network = dds.profile_path(), dds.profile_path(network=True)
    assert local.name == 'fastdds.xml' and network.name == 'fastdds_network.xml'
    for env, chosen in [({}, local), ({'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}, local),
                        ({'ROS_AUTOMATIC_DISCOVERY_RANGE': 'OFF'}, local),
                        ({'ROS_STATIC_PEERS': ' '}, local),
                        ({'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SUBNET'}, network),
                        ({'ROS_AUTOMATIC_DISCOVERY_RANGE': 'system_default'}, network),
                        ({'ROS_STATIC_PEERS': '192.168.1.7'}, network)]:
        assert dds.profile_environment(env) == {n: str(chosen) for n in dds.PROFILE_VARIABLES}


def _udp_sockets(env: Dict[str, str]) -> List[str]:
    """The local addresses (ip:port) of the UDP sockets a fresh node process opens."""
    child = subprocess.Popen([sys.executable, '-c', CHILD], env=env, stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        line = child.stdout.readline()
        assert line.strip() == 'ready', line + child.stdout.read()
        inodes = set()
        for fd in Path(f'/proc/{child.pid}/fd').iterdir():
            try:
                target = os.readlink(fd)
            except OSError:
                continue
            if target.startswith('socket:['):
                inodes.add(target[len('socket:['):-1])
        found = []
        for row in Path(f'/proc/{child.pid}/net/udp').read_text().splitlines()[1:]:
            fields = row.split()
            if fields[9] in inodes:
                ip, port = fields[1].split(':')
                found.append(f'{socket.inet_ntoa(struct.pack("<I", int(ip, 16)))}:{int(port, 16)}')
        return found
    finally:
        child.stdin.close()
        child.wait(timeout=30)


@pytest.mark.skipif(not Path('/proc/self/net/udp').exists(), reason='needs /proc')
def test_a_node_listens_on_no_interface_but_loopback_unless_the_network_is_asked_for():
    """Issue 15, finding 9: every node bound its DDS sockets on all interfaces, so anyone on
    the network could drive the robots. With the default profile each socket is bound to
    127.0.0.1 (or to a multicast group, joined on loopback only)."""
    base = {k: v for k, v in os.environ.items()
            if k not in dds.PROFILE_VARIABLES + ('ROS_AUTOMATIC_DISCOVERY_RANGE',
                                                 'ROS_STATIC_PEERS')}
    local = _udp_sockets(dds.with_profile(base))
    assert local and all(a.startswith('127.') or a.startswith('239.') for a in local), local
    opened = _udp_sockets(dds.with_profile({**base, 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SUBNET'}))
    assert any(a.startswith('0.0.0.0:') for a in opened), opened


def test_the_installed_profiles_are_the_source_files():
    for network, source in ((False, SOURCE_PROFILE), (True, NETWORK_PROFILE)):
        installed = dds.profile_path(network)
        assert installed is not None
        assert installed.read_bytes() == source.read_bytes()


def test_a_launcher_adds_the_profile_only_where_none_is_chosen():
    path = str(dds.profile_path())
    assert dds.profile_environment({}) == {name: path for name in dds.PROFILE_VARIABLES}
    assert dds.with_profile({'A': '1'}) == {'A': '1', **{n: path
                                                          for n in dds.PROFILE_VARIABLES}}
    # A user's profile wins, whichever of the two variables names it.
    for name in dds.PROFILE_VARIABLES:
        assert dds.profile_environment({name: '/mine.xml'}) == {}
        assert dds.with_profile({name: '/mine.xml'}) == {name: '/mine.xml'}
    # Another middleware gets no Fast DDS file.
    assert dds.profile_environment({'RMW_IMPLEMENTATION': 'rmw_cyclonedds_cpp'}) == {}
    assert dds.profile_environment({'RMW_IMPLEMENTATION': 'rmw_fastrtps_dynamic_cpp'})


def test_the_test_session_runs_with_the_profile_as_every_launcher_sets_it():
    # scripts/test.sh sources scripts/env.sh, as a user's shell does.
    assert os.environ.get('FASTRTPS_DEFAULT_PROFILES_FILE') == str(dds.profile_path())


def _segments_mapped(env: Dict[str, str]) -> List[int]:
    """Sizes of the Fast DDS shared-memory segments a fresh node process maps: its own, with
    discovery off (a participant it discovers, such as a node of another test still shutting
    down on a busy machine, has its segment mapped too: 8 MiB with the profile)."""
    env = {**env, 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'OFF'}
    child = subprocess.Popen([sys.executable, '-c', CHILD], env=env, stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        line = child.stdout.readline()
        assert line.strip() == 'ready', line + child.stdout.read()
        sizes: Dict[str, int] = {}
        for row in Path(f'/proc/{child.pid}/maps').read_text().splitlines():
            fields = row.split()
            name = fields[-1] if len(fields) >= 6 else ''
            if name.startswith('/dev/shm/fastrtps_') and 'port' not in name:
                start, end = (int(x, 16) for x in fields[0].split('-'))
                sizes[name] = sizes.get(name, 0) + end - start
        return sorted(sizes.values())
    finally:
        child.stdin.close()
        child.wait(timeout=30)


@pytest.mark.skipif(not Path('/proc/self/maps').exists(), reason='needs /proc')
def test_fast_dds_maps_the_profiles_segment_and_the_default_one_without_it():
    base = {k: v for k, v in os.environ.items() if k not in dds.PROFILE_VARIABLES}
    with_profile = _segments_mapped(dds.with_profile(base))
    without = _segments_mapped(base)
    assert with_profile and max(with_profile) >= dds.SEGMENT_SIZE
    assert without and max(without) < 1024 * 1024     # Fast DDS's own 512 KiB


PLACEMENT = '''
import ctypes, sys
from ros_common.memory import keep_large_blocks
if sys.argv[1] == 'keep':
    assert keep_large_blocks()
def on_heap(block):
    address = ctypes.addressof((ctypes.c_char * len(block)).from_buffer(block))
    for row in open('/proc/self/maps'):
        if row.rstrip().endswith('[heap]'):
            start, end = (int(x, 16) for x in row.split()[0].split('-'))
            if start <= address < end:
                return True
    return False
frames = [bytearray(4 << 20) for _ in range(3)]
print(sum(on_heap(f) for f in frames))
'''


@pytest.mark.skipif(not Path('/proc/self/maps').exists(), reason='needs /proc')
def test_large_blocks_come_from_the_heap_instead_of_a_mapping_each():
    def on_heap(mode: str) -> int:
        return int(subprocess.run([sys.executable, '-c', PLACEMENT, mode], check=True,
                                  text=True, capture_output=True).stdout)

    # glibc's default: a mapping of its own per block, unmapped (its pages lost) on free.
    assert on_heap('default') == 0
    assert on_heap('keep') == 3
