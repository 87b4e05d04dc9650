"""`rad train --actors N` and `--seeds` (rad_core.training.actors) on Dask workers on loopback.

One cluster of two worker processes (rad's own `dask_client`, 127.0.0.1) serves the module.
Tiny configs and a small network keep each training to seconds. The serial path's own
determinism and resume tests are tests/core/test_dqn.py's.
"""

import socket
import subprocess
import sys

import pytest
import torch
from rad_core.domain.errors import RadError
from rad_core.experiment.distributed import dask_client
from rad_core.learning.policy import QPolicy
from rad_core.training.actors import ActorConfig, DistributedTrainer, seed_folder, train_seeds, train_with_actors
from rad_core.training.dqn import TrainConfig, train
from training import SMALL_NET_FLAGS, tiny_dataset
from training import tiny as tiny_config


@pytest.fixture(scope='module')
def dataset(tmp_path_factory):
    return tiny_dataset(tmp_path_factory.mktemp('data'))


@pytest.fixture(scope='module')
def client():
    with dask_client(workers=2) as c:
        yield c


def tiny(dataset, **kw) -> TrainConfig:
    return tiny_config(dataset, **{'eval_scenes': 2, **kw})


def same_weights(a, b) -> bool:
    return a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def test_two_actors_feed_the_learner_which_checkpoints_and_resumes(dataset, tmp_path, client):
    actor = ActorConfig(actors=2, chunk_steps=16, refresh_every=5)
    result = train_with_actors(tiny(dataset, total_steps=160), tmp_path / 'run', actor, client=client)
    assert not result['interrupted']
    assert result['env_steps'] >= 160 and result['received'] == result['env_steps']
    assert result['grad_steps'] > 0 and result['tasks'] >= 2 + 160 // 40
    doc = torch.load(tmp_path / 'run' / 'checkpoint.pt', weights_only=False)
    assert doc['position']['env_steps'] == result['env_steps']
    assert len(doc['replay']['items']) == min(500, result['env_steps'])   # every transition came from an actor
    policy = QPolicy.load(tmp_path / 'run' / 'model.pt')
    assert policy.actions == 'milp'
    rows = (tmp_path / 'run' / 'progress.csv').read_text().splitlines()
    assert rows[0].startswith('env_steps,grad_steps') and len(rows) >= 3
    # Resume, extended: continues from the checkpoint's position and replay.
    again = train_with_actors(TrainConfig(), tmp_path / 'run', actor, resume=True, total_steps=240, client=client)
    assert again['env_steps'] >= 240 and again['received'] == again['env_steps'] - result['env_steps']
    assert again['tasks'] > result['tasks']
    assert not same_weights(doc['weights'], torch.load(tmp_path / 'run' / 'model.pt', weights_only=True)['weights'])


def test_actors_refresh_their_weights_from_the_learner(dataset, tmp_path, client):
    trainer = DistributedTrainer(tiny(dataset, total_steps=200, eval_every=1000), tmp_path / 'run',
                                 ActorConfig(actors=2, chunk_steps=8, refresh_every=2))
    trainer.run(client=client)
    # Later tasks act with newer weights than the first ones, and the lag (learner's version
    # minus the task's) stays a few publications: one task's worth of gradient steps per actor.
    learner, task = zip(*trainer.versions)
    assert max(learner) >= 10 and max(task) >= max(learner) - 8
    assert max(a - b for a, b in trainer.versions) <= 8, trainer.versions


def test_seeds_give_each_seed_the_standalone_run(dataset, tmp_path, client):
    cfg = tiny(dataset)
    done = []
    train_seeds(cfg, tmp_path / 'multi', [1, 2], client=client, progress=lambda s, r: done.append(s))
    assert sorted(done) == [1, 2]
    for seed in (1, 2):
        train(tiny(dataset, seed=seed), tmp_path / f'alone-{seed}')
        alone = torch.load(tmp_path / f'alone-{seed}' / 'model.pt', weights_only=True)['weights']
        multi = torch.load(seed_folder(tmp_path / 'multi', seed) / 'model.pt', weights_only=True)['weights']
        assert same_weights(alone, multi), f'seed {seed} differs from its standalone run'
    with pytest.raises(RadError, match='already holds a training run'):
        train_seeds(cfg, tmp_path / 'multi', [2, 3], client=client)


def rad_train(*args):
    return subprocess.run([sys.executable, '-m', 'rad_core.cli', 'train', *args], capture_output=True, text=True,
                          timeout=120)


@pytest.mark.parametrize('flags, message', [
    (['--actors', '0'], '--actors must be at least 1'),
    (['--actors', '-2'], '--actors must be at least 1'),
    (['--actors', '2', '--seeds', '1,2'], 'do not combine'),
    (['--seeds', '1,2', '--seed', '3'], '--seed and --seeds do not combine'),
    (['--seeds', '1,x'], '--seeds takes whole numbers'),
    (['--scheduler', 'tcp://127.0.0.1:1'], '--scheduler applies to --actors N or --seeds'),
    (['--refresh-every', '5'], '--refresh-every applies to --actors N only'),
    (['--actors', '2', '--robot'], 'does not support --robot'),
])
def test_bad_flag_combinations_are_one_line_errors(dataset, tmp_path, flags, message):
    r = rad_train('--out', str(tmp_path / 'run'), '--dataset', str(dataset), '--total-steps', '10', *flags)
    assert r.returncode == 2 and r.stderr.strip().count('\n') == 0, r.stderr
    assert message in r.stderr, r.stderr
    assert not (tmp_path / 'run' / 'checkpoint.pt').exists()


def test_bad_actor_config_is_refused_before_any_cluster_starts(dataset, tmp_path):
    for bad in (ActorConfig(actors=0), ActorConfig(chunk_steps=0), ActorConfig(refresh_every=-1)):
        with pytest.raises(RadError, match='must be a whole number of at least 1'):
            train_with_actors(tiny(dataset), tmp_path / 'run', bad)
    with pytest.raises(RadError, match='lists a seed twice'):
        train_seeds(tiny(dataset), tmp_path / 'multi', [1, 1])


def test_cli_actors_starts_its_own_loopback_cluster_and_trains(dataset, tmp_path):
    """A real `rad train --actors 2`: while it runs, every listening or bound socket of its process
    tree is on loopback, and no packet leaves by a non-loopback interface."""
    import ipaddress
    import time

    import psutil
    from ros_harness import interface_tx_packets, non_loopback
    argv = [sys.executable, '-m', 'rad_core.cli', 'train', '--out', str(tmp_path / 'run'), '--dataset', str(dataset),
            '--total-steps', '60', '--learning-starts', '20', '--batch-size', '8', '--eval-every', '60',
            '--eval-scenes', '1', '--actors', '2', '--chunk-steps', '10',
            *SMALL_NET_FLAGS]
    before = non_loopback(interface_tx_packets())
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    seen, deadline = [], time.monotonic() + 120
    while proc.poll() is None and time.monotonic() < deadline:
        try:
            tree = [psutil.Process(proc.pid), *psutil.Process(proc.pid).children(recursive=True)]
            for p in tree:
                seen += [c for c in p.net_connections(kind='inet')
                         if c.status == psutil.CONN_LISTEN or c.type == socket.SOCK_DGRAM]
        except psutil.Error:
            pass   # a process of the tree ended between the listing and the look
        time.sleep(0.2)
    out, err = proc.communicate(timeout=30)
    sent = {name: n for name, n in non_loopback(interface_tx_packets()).items() if n > before.get(name, 0)}
    assert proc.returncode == 0, err
    assert out.startswith('done') or '\ndone:' in out, out
    assert any(c.status == psutil.CONN_LISTEN for c in seen), 'expected the cluster\'s listeners'
    def loopback(ip: str) -> bool:
        address = ipaddress.ip_address(ip.split('%')[0])
        return (getattr(address, 'ipv4_mapped', None) or address).is_loopback
    off = [c for c in seen if not loopback(c.laddr.ip)]
    assert off == [], off
    assert sent == {}, f'packets sent on non-loopback interfaces during training: {sent}'
    assert QPolicy.load(tmp_path / 'run' / 'model.pt').actions == 'milp'
