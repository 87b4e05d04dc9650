"""`rad eval --workers N` (rad_core.experiment.distributed): the serial run's rows from Dask workers on loopback.

One cluster of two worker processes, started by rad's own `dask_client` on 127.0.0.1 the way
`rad eval --workers 2` starts it (forked from this process, `START_METHOD`), serves the whole
module; the kill test leaves it whole again (the nanny restarts the worker it kills).
"""

import ipaddress
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time

import psutil
import pytest
from rad_core.domain.errors import RadError
from rad_core.domain.scene_sources import generated_scenes
from rad_core.experiment.distributed import (
    START_METHOD,
    AgentArgs,
    WarmUp,
    dask_client,
    evaluate_distributed,
    scene_cost,
)
from rad_core.experiment.evaluation import evaluate

SCENES = list(generated_scenes(3, 2, 6, 0))
SEED = 5


def rad(*args, timeout=120):
    exe = shutil.which('rad')
    cmd = [exe] if exe else [sys.executable, '-m', 'rad_core.cli']
    return subprocess.run(cmd + list(args), check=False, capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope='module')
def client():
    with dask_client(workers=2, start_method=START_METHOD) as c:
        yield c


@pytest.fixture(scope='module')
def serial():
    """The serial results the distributed runs must reproduce, by agent."""
    return {'heur-norobot': evaluate('heur-norobot', SCENES, robot=False, seed=SEED),
            'heur': evaluate('heur', SCENES, robot=True, seed=SEED)}


@pytest.mark.parametrize('agent, robot', [('heur-norobot', False), ('heur', True)])
def test_two_workers_give_exactly_the_serial_rows_and_metrics(client, serial, agent, robot):
    seen = []
    result = evaluate_distributed(AgentArgs(agent), SCENES, robot, SEED, progress=seen.append, client=client)
    assert result == serial[agent]
    assert [r['name'] for r in result['scenes']] == [name for name, _ in SCENES]
    assert sorted(r['name'] for r in seen) == sorted(name for name, _ in SCENES)


def built_here(agent: str, robot: bool):
    """What this worker thread has built for the agent: (agents, planners, stability check)."""
    from rad_core.experiment import distributed
    state = getattr(distributed._local, 'state', None) or {}
    return ([a.agent for a in state.get('agents', {})], [k[0].agent for k in state.get('planners', {})],
            state.get('stability') is not None)


def test_every_worker_is_warm_before_the_first_scene_and_workers_that_join_later_too(client):
    """warm_up builds the agent, its network and the planner's worlds on every worker, the one
    that gets no scene included; a worker plugin, so one that joins later is warm as it joins."""
    from rad_core.experiment.distributed import warm_up
    name = warm_up(client, AgentArgs('heur'), True)
    assert name == WarmUp(AgentArgs('heur'), True).name   # by settings: a second run finds it

    def assert_all_warm(n):
        workers = list(client.nthreads())    # (scheduler_info's workers can come back empty: a race in distributed)
        assert len(workers) == n
        for w in workers:
            agents, planners, _ = client.submit(built_here, 'heur', True, workers=[w], pure=False).result()
            assert 'heur' in agents and 'heur' in planners, (w, agents, planners)
    try:
        assert_all_warm(2)
        client.cluster.scale(3)
        client.wait_for_workers(3, timeout=60)
        assert_all_warm(3)
    finally:
        client.unregister_worker_plugin(name)
        client.cluster.scale(2)
        deadline = time.monotonic() + 60
        while len(client.nthreads()) != 2 and time.monotonic() < deadline:
            time.sleep(0.1)
    assert len(client.nthreads()) == 2


def worker_upkeep(dask_worker) -> dict:
    import dask
    worker = dask_worker
    return {'tick': dask.config.get('distributed.admin.tick.interval'),
            'profile': dask.config.get('distributed.worker.profile.enabled'),
            'profiler_running': worker.periodic_callbacks.get('profile') is not None
            and worker.periodic_callbacks['profile'].is_running()}


def test_workers_keep_their_own_upkeep_rare(client):
    """Each local worker runs with `QUIET_WORKER`: the event loop's health check every second and
    no statistical profiler sampling the thread that plans the scenes."""
    upkeep = client.run(worker_upkeep)
    assert len(upkeep) == 2
    for found in upkeep.values():
        assert found == {'tick': '1s', 'profile': False, 'profiler_running': False}, found


def test_scenes_go_out_longest_first():
    """The scenes run by scene_cost, the largest first (so two workers finish together); the rows
    stay in scene order. One worker, so the order they start in is the order they went out in."""
    from distributed import get_task_stream
    costs = [scene_cost(s) for _, s in SCENES]
    assert costs != sorted(costs, reverse=True), 'the scenes are in cost order already: nothing tested'
    with dask_client(workers=1, start_method=START_METHOD) as client, get_task_stream(client=client) as stream:
        result = evaluate_distributed(AgentArgs('heur-norobot'), SCENES, False, SEED, client=client)
    assert [r['name'] for r in result['scenes']] == [name for name, _ in SCENES]
    started = sorted((min(s['start'] for s in t['startstops'] if s['action'] == 'compute'), int(t['key'][-6:]))
                     for t in stream.data if str(t['key']).startswith('rad-scene-'))
    assert sorted(i for _, i in started) == list(range(len(SCENES)))
    in_start_order = [costs[i] for _, i in started]
    assert in_start_order == sorted(costs, reverse=True), in_start_order


def torch_in_worker():
    """A matrix product big enough for torch to go parallel, and the thread count it ran on."""
    import torch
    a = torch.ones(400, 400)
    return float((a @ a).sum()), torch.get_num_threads()


def test_workers_forked_after_torch_ran_on_threads_run_torch_on_one_and_start_warm():
    """A worker forked from a process whose torch already ran OpenMP threads hangs in its first
    parallel product unless torch is back on one thread first (dask_setup); and it starts with
    what this process imported (torch here) instead of importing it again."""
    import torch
    if START_METHOD != 'fork':
        pytest.skip('workers are spawned on this platform')
    threads = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        a = torch.ones(400, 400)
        assert float((a @ a).sum()) == 400.0 ** 3
        with dask_client(workers=1, start_method='fork') as c:
            assert all(c.run(lambda: 'torch' in sys.modules).values())
            total, n = c.submit(torch_in_worker, pure=False).result(timeout=60)
        assert (total, n) == (400.0 ** 3, 1)
    finally:
        torch.set_num_threads(threads)


def is_loopback(ip: str) -> bool:
    address = ipaddress.ip_address(ip.split('%')[0])
    mapped = getattr(address, 'ipv4_mapped', None)
    return (mapped or address).is_loopback


def sockets_of(pids):
    """(pid, kind, local, remote, status) of every inet socket of the processes."""
    found = []
    for pid in pids:
        for c in psutil.Process(pid).net_connections(kind='inet'):
            found.append((pid, c.type, c.laddr, c.raddr, c.status))
    return found


def non_loopback_tx() -> dict:
    """Packets sent so far per non-loopback interface (as the DDS loopback test counts them)."""
    from ros_harness import interface_tx_packets, non_loopback
    return non_loopback(interface_tx_packets())


def test_every_socket_of_the_cluster_is_on_loopback_while_it_runs(client):
    worker_pids = set(client.run(os.getpid).values())
    assert len(worker_pids) == 2
    snapshots = []

    def look(_row):   # during the run: the scheduler and nannies live in this process
        if not snapshots:
            procs = {os.getpid(), *worker_pids, *(p.pid for p in psutil.Process().children(recursive=True))}
            snapshots.append(sockets_of(procs))

    before = non_loopback_tx()
    evaluate_distributed(AgentArgs('heur'), SCENES, True, SEED, progress=look, client=client)
    sent = {name: n for name, n in non_loopback_tx().items() if n > before.get(name, 0)}
    assert sent == {}, f'packets sent on non-loopback interfaces during the run: {sent}'
    found = snapshots[0]
    listening = [s for s in found if s[4] == psutil.CONN_LISTEN]
    assert {pid for pid, *_ in listening} >= worker_pids | {os.getpid()}, 'expected the cluster\'s listeners'
    assert all(is_loopback(s[2].ip) for s in listening), [s for s in listening if not is_loopback(s[2].ip)]
    bound_udp = [s for s in found if s[1] == socket.SOCK_DGRAM]
    assert all(is_loopback(s[2].ip) for s in bound_udp), bound_udp
    remote = [s for s in found if s[3]]
    assert remote and all(is_loopback(s[3].ip) for s in remote), [s for s in remote if not is_loopback(s[3].ip)]


def test_a_worker_killed_mid_run_loses_no_scene_and_counts_none_twice(client, serial):
    killed = {}

    def kill_a_busy_worker(_row):
        if killed:
            return
        busy = {w: keys for w, keys in client.processing().items() if keys}
        if not busy:
            return
        address, keys = next(iter(busy.items()))
        pid = client.run(os.getpid, workers=[address])[address]
        os.kill(pid, signal.SIGKILL)
        killed.update(address=address, keys=keys, pid=pid)

    seen = []

    def progress(row):
        seen.append(row['name'])
        kill_a_busy_worker(row)

    result = evaluate_distributed(AgentArgs('heur'), SCENES, True, SEED, progress=progress, client=client)
    assert killed, 'no worker was busy after the first row: nothing was killed'
    assert not psutil.pid_exists(killed['pid']) or psutil.Process(killed['pid']).status() == psutil.STATUS_ZOMBIE
    assert result == serial['heur']
    assert sorted(seen) == sorted(name for name, _ in SCENES)

    def story(dask_scheduler, key=killed['keys'][0]):
        return [(start, finish) for _, start, finish, *_ in dask_scheduler.story(key)]
    transitions = client.run_on_scheduler(story)
    assert transitions.count(('waiting', 'processing')) + transitions.count(('queued', 'processing')) >= 2, \
        f'the killed worker\'s task was not run again: {transitions}'
    client.wait_for_workers(2, timeout=60)   # the nanny's replacement, for the tests after this one


def test_cli_workers_and_scheduler_give_the_serial_json(client, tmp_path):
    expected = evaluate('heur-norobot', SCENES[:3], robot=False, seed=0)
    for flags in (['--workers', '2'], ['--scheduler', client.cluster.scheduler_address, '--workers', '2']):
        out = tmp_path / 'out.json'
        r = rad('eval', '--agent', 'heur-norobot', '--grid', '3', '--scenes', '3', '--seed', '0',
                '--json', str(out), *flags)
        assert r.returncode == 0, r.stderr
        assert 'heur on 3 scenes' in r.stdout and 'Dask' in r.stdout
        assert json.loads(out.read_text()) == expected


def closed_port() -> int:
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


def test_cli_bad_workers_and_an_unreachable_scheduler_are_one_line_errors():
    r = rad('eval', '--agent', 'heur-norobot', '--grid', '3', '--scenes', '1', '--workers', '0')
    assert r.returncode == 2 and r.stderr.strip().count('\n') == 0, r.stderr
    assert '--workers must be at least 1' in r.stderr
    t0 = time.perf_counter()
    r = rad('eval', '--agent', 'heur-norobot', '--grid', '3', '--scenes', '1',
            '--scheduler', f'tcp://127.0.0.1:{closed_port()}', timeout=60)
    assert r.returncode == 2 and r.stderr.strip().count('\n') == 0, r.stderr
    assert 'cannot reach the Dask scheduler' in r.stderr
    assert time.perf_counter() - t0 < 30


def test_a_scheduler_that_accepts_but_never_answers_times_out():
    with socket.socket() as silent:
        silent.bind(('127.0.0.1', 0))
        silent.listen()
        address = f'tcp://127.0.0.1:{silent.getsockname()[1]}'
        t0 = time.perf_counter()
        with pytest.raises(RadError, match='cannot reach the Dask scheduler'):
            with dask_client(scheduler=address, connect_timeout_s=1.0):
                pass
        assert time.perf_counter() - t0 < 10


def test_bad_arguments_fail_before_any_cluster_starts():
    for workers in (0, -1):
        with pytest.raises(RadError, match='--workers'):
            evaluate_distributed(AgentArgs('heur-norobot'), SCENES, False, 0, workers=workers)
    with pytest.raises(RadError, match='no scenes'):
        evaluate_distributed(AgentArgs('heur-norobot'), [], False, 0, workers=1)
    with pytest.raises(RadError, match="unknown scorer 'nobody'"):
        evaluate_distributed(AgentArgs('nobody'), SCENES, False, 0, workers=1)
    with pytest.raises(RadError, match='--dashboard'):
        with dask_client(scheduler='tcp://127.0.0.1:1', dashboard=True):
            pass
