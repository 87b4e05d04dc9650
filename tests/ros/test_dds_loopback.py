"""Proof that DDS stays on loopback under the project's settings (scripts/env.sh).

What Fast DDS 2.14 does here (measured): with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST,
rmw_fastrtps_cpp appends its own SHM and an un-whitelisted UDPv4 transport to the
profile's transports. Our whitelisted UDPv4 transport comes first and binds every
receive port on 127.0.0.1; the rmw's transport then cannot bind them (EADDRINUSE) and
keeps only send sockets, one of them bound to the non-loopback address for multicast,
which nothing ever uses (there are no multicast destinations). Without the profile,
the receive ports are bound on 0.0.0.0 and the participant advertises every address.

So the checks are: (a) the variables reach a node process, (b) the profile says what
it should, (c) every DDS receive socket is on 127.0.0.1 and no non-loopback interface
sends a packet while nodes talk; and, in private network namespaces with a veth pair
(nothing there can leave the machine), negative controls showing that the same checks
fail without the profile and with plain Fast DDS.
"""

from __future__ import annotations

import os
import random
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import ros_harness as harness

CHATTER = Path(__file__).parent / 'nodes' / 'chatter_node.py'
NS = {'f': 'http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles'}


def domain_id() -> int:
    return int(os.environ['ROS_DOMAIN_ID'])


def start_chatter(process, name='chatter', env=None, prefix=()):
    proc = process([*prefix, sys.executable, CHATTER, *harness.ros_args({'period_s': 0.02})],
                   name=name, env=env)
    proc.wait_for_output('chatter ready', timeout=15)
    return proc


def test_profile_whitelists_only_loopback():
    path = Path(os.environ['FASTRTPS_DEFAULT_PROFILES_FILE'])
    assert path == harness.PROFILE_FILE and os.environ['FASTDDS_DEFAULT_PROFILES_FILE'] == str(path)
    root = ET.parse(path).getroot()

    defaults = [p for p in root.iterfind('f:participant', NS)
                if p.get('is_default_profile') == 'true']
    assert len(defaults) == 1, 'exactly one default participant profile'
    rtps = defaults[0].find('f:rtps', NS)
    assert rtps.findtext('f:useBuiltinTransports', namespaces=NS).strip() == 'false'

    descriptors = {d.findtext('f:transport_id', namespaces=NS): d
                   for d in root.iterfind('f:transport_descriptors/f:transport_descriptor', NS)}
    used = [descriptors[t.text.strip()]
            for t in rtps.iterfind('f:userTransports/f:transport_id', NS)]
    assert sorted(d.findtext('f:type', namespaces=NS) for d in used) == ['SHM', 'UDPv4']
    for d in used:
        if d.findtext('f:type', namespaces=NS) == 'UDPv4':
            whitelist = [a.text.strip() for a in d.iterfind('f:interfaceWhiteList/*', NS)]
            assert whitelist == ['127.0.0.1']


@pytest.mark.parametrize('path', [harness.PROFILE_FILE, harness.REPO_ROOT / 'docs' / 'examples' / 'fastdds_lan.xml'],
                         ids=['loopback', 'lan example'])
def test_service_responses_wait_for_a_slow_discovery(path):
    """rmw_fastrtps drops a response when the client's response reader is not matched within the
    response writer's max_blocking_time (100 ms by default): a loaded machine lost an /allocate
    answer that way. Both profiles give service response writers (profile "service") seconds."""
    root = ET.parse(path).getroot()
    service = [p for p in root.iterfind('f:publisher', NS) if p.get('profile_name') == 'service']
    assert len(service) == 1, f'{path.name}: one publisher profile named "service"'
    wait = service[0].find('f:qos/f:reliability/f:max_blocking_time', NS)
    seconds = int(wait.findtext('f:sec', '0', NS)) + int(wait.findtext('f:nanosec', '0', NS)) * 1e-9
    assert seconds >= 2.0


def test_node_process_runs_with_dds_settings(process):
    chatter = start_chatter(process)
    environ = harness.read_proc_environ(chatter.pid)
    assert harness.dds_env_problems(environ) == []
    assert environ['ROS_DOMAIN_ID'] == os.environ['ROS_DOMAIN_ID']
    assert chatter.stop() == 0, chatter.output_tail()


def test_traffic_between_processes_stays_on_loopback(process, ros_node):
    from std_msgs.msg import String
    from std_srvs.srv import Trigger

    before = harness.non_loopback(harness.interface_tx_packets())
    chatter = start_chatter(process)
    received = []
    ros_node.create_subscription(String, 'chatter', lambda msg: received.append(msg.data), 10)
    client = harness.wait_for_service(ros_node, Trigger, 'ping', timeout=10)
    assert harness.spin_until(ros_node, lambda: len(received) >= 20, timeout=10), received
    response = harness.call_service(ros_node, client, Trigger.Request(), timeout=5)
    assert response.success, response.message

    for pid in (chatter.pid, os.getpid()):
        loopback, elsewhere = harness.non_loopback_receive_sockets(pid, domain_id())
        assert loopback, f'pid {pid} holds no DDS receive socket: {harness.udp_sockets(pid)}'
        assert elsewhere == [], f'DDS receive sockets off loopback: {elsewhere}'
    after = harness.non_loopback(harness.interface_tx_packets())
    assert chatter.stop() == 0, chatter.output_tail()
    sent = {name: n for name, n in harness.delta(before, after).items() if n}
    assert sent == {}, f'packets sent on non-loopback interfaces during DDS traffic: {sent}'


# --- negative controls, each in a private network namespace ------------------------------

# A namespace with loopback and a veth pair: rad0 stands in for eth0 (address and
# default route), its peer rad1 sits in the same namespace, so nothing sent on rad0
# can leave the machine. IPv6 is off so that the kernel itself sends nothing on rad0.
NETNS_SETUP = r'''
set -e
echo 1 > /proc/sys/net/ipv6/conf/all/disable_ipv6
echo 1 > /proc/sys/net/ipv6/conf/default/disable_ipv6
ip link set lo up
ip link add rad0 type veth peer name rad1
ip addr add 10.213.0.2/24 dev rad0
ip link set rad0 up
ip link set rad1 up
ip route add default via 10.213.0.1 dev rad0
exec "$@"
'''
NETNS = ('unshare', '--net', 'bash', '-c', NETNS_SETUP, 'netns')


def netns_available() -> bool:
    try:
        probe = subprocess.run([*NETNS, 'true'], check=False, capture_output=True, timeout=10)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return probe.returncode == 0


@pytest.mark.skipif(not netns_available(),
                    reason='needs unshare --net and ip (root): no private network namespace')
def test_checks_fail_without_the_settings(process):
    # A domain whose RTPS ports (7400 + 250 * domain ...) lie below Linux's ephemeral ports (32768 up),
    # as the session's own does (tests/conftest.py): domains from 102 on share their range with them,
    # and an ephemeral socket a library opened on 0.0.0.0 once landed in it and read as a DDS
    # receive socket off loopback.
    domain = str(random.randrange(1, 97))
    project = dict(os.environ, ROS_DOMAIN_ID=domain, RAD_ROS_DOMAIN_ID=domain)
    no_profile = {k: v for k, v in project.items() if 'DEFAULT_PROFILES_FILE' not in k}
    plain = dict(no_profile, ROS_AUTOMATIC_DISCOVERY_RANGE='SUBNET',
                 ROS_DOMAIN_ID=str(random.randrange(100, 200)))
    scenarios = {'project': project, 'no_profile': no_profile, 'plain_fastdds': plain}
    procs = {name: start_chatter(process, name, env, prefix=NETNS)
             for name, env in scenarios.items()}
    time.sleep(1.0)  # discovery announcements go out in the first second

    sent, off_loopback, on_loopback = {}, {}, {}
    for name, proc in procs.items():
        sent[name] = harness.interface_tx_packets(proc.pid)['rad0']
        on_loopback[name], off_loopback[name] = harness.non_loopback_receive_sockets(
            proc.pid, int(scenarios[name]['ROS_DOMAIN_ID']))
    exit_codes = {name: proc.stop() for name, proc in procs.items()}
    report = f'rad0 tx packets {sent}; receive sockets off loopback {off_loopback}'

    # The project's settings: all receive sockets on loopback, nothing sent on rad0.
    assert on_loopback['project'] and off_loopback['project'] == [], report
    assert sent['project'] == 0, report
    # The socket check catches a profile that was not loaded ...
    assert off_loopback['no_profile'], report
    # ... and the packet counter catches DDS discovery on a non-loopback interface.
    assert sent['plain_fastdds'] > 0, report
    assert exit_codes == dict.fromkeys(procs, 0), exit_codes
